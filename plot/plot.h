// A minimal SVG figure: one plot area with axes on round ("nice", 1-2-5)
// ticks or a log axis on decades, lines, scatter with error bars and marker
// shapes, bars, contour lines of a gridded field (marching squares), a heat
// map with its colour bar (continuous, or classes), and a legend with an
// entry for every mark; several figures side by side in one SVG (PanelsSvg).
// No plotting dependency and nothing of fluxcal: every SVG that fluxcal
// writes (the report page, the fit, table and diagnosis plots) is built
// from it, so that no other folder writes SVG elements by hand.
//
// Layout rules the figure keeps so that a page of them reads at a glance:
//   - axis ranges are extended to whole tick steps, so the frame starts and
//     ends on a labelled tick;
//   - marks are clipped to the plot area; labels, colour bar and legend sit
//     outside it and inside the SVG's own width and height (a title too long
//     for the width is wrapped, a legend too tall for it gets more columns);
//   - every mark added with a non-empty label gets a legend entry.
// Ids inside the SVG (clip paths) are prefixed with the figure's id, so
// several figures can be inlined in one HTML document.
//
// Elements carry a class for tests and style sheets: "line", "contour",
// "point" (scatter markers), "bar", "below-floor" (a bar under a log axis's
// floor), "cell" (heat-map cells); groups "xticks", "yticks", "colourbar"
// and "legend" hold the axes' tick labels, the colour bar and the legend.
#ifndef FLUXCAL_PLOT_PLOT_H_
#define FLUXCAL_PLOT_PLOT_H_

#include <cstddef>
#include <optional>
#include <string>
#include <utility>
#include <vector>

namespace fluxcal::plot {

// Tick positions covering [lo, hi] with a step of 1, 2 or 5 times a power
// of ten, the count closest to `target` ticks; the first tick <= lo, the
// last >= hi.
// lo == hi (or non-finite input) gives a unit-wide range around lo.
std::vector<double> NiceTicks(double lo, double hi, int target = 5);
// Tick label: as few digits as the step needs ("0.05", "120", "1e-05").
std::string FormatTick(double value, double step);
// Label of the decade 10^exponent on a log axis: plain digits from 0.001
// to 10000 ("0.01", "100"), "1e-05" / "1e+06" beyond.
std::string FormatDecade(int exponent);

// Marching squares over z sampled at (xs[i], ys[j]), z[j * xs.size() + i]
// (row-major, y slowest). Returns the level set z == level as polylines
// (segments joined where they meet). NaN cells are skipped; saddle cells are
// resolved by the cell's mean.
using Polyline = std::vector<std::pair<double, double>>;
std::vector<Polyline> ContourLines(const std::vector<double>& xs, const std::vector<double>& ys,
                                   const std::vector<double>& z, double level);

// Curves that would be drawn on top of each other: ys[k] are curves sampled
// at the same abscissae; curve k joins the group of the first earlier curve
// that differs from it by at most `tol` at every sample where both are
// finite. Returns, for each curve, the index of its group's first curve
// (itself when it starts a group). Lets a caller draw one line with one
// legend entry ("iq = 0, 20, 40 A") instead of several hidden under it.
std::vector<size_t> CoincidentGroups(const std::vector<std::vector<double>>& ys, double tol);

// Colour of u in [0, 1] on a perceptually ordered map (viridis anchors),
// as "#rrggbb".
std::string ColourMap(double u);
// The i-th of a set of distinct line colours (cycled).
std::string Palette(int i);
// Text escaped for XML / HTML content and attribute values (& < > ").
std::string Escape(const std::string& s);

// Marker shapes for scatter points: a filled dot for data, the others for
// points that mean something else (a clamped or an extrapolated table cell,
// a value off the axis) and so must not look like data.
enum class Marker {
  kDot,            // filled circle
  kRing,           // open circle
  kCross,          // diagonal cross
  kSquare,         // open square
  kTriangleDown,   // filled triangle pointing down
};

// Where a curve's values come from, and its dash: the one key of every
// figure (the report page's and the exported tables' alike): solid
// measured, dashed by symmetry, dotted extrapolated.
enum class Provenance { kMeasured = 0, kBySymmetry = 1, kExtrapolated = 2 };
inline const char* ProvenanceDash(Provenance p) {
  switch (p) {
    case Provenance::kMeasured: return "";
    case Provenance::kBySymmetry: return "8 4";
    case Provenance::kExtrapolated: return "2 3";
  }
  return "";
}

struct Style {
  std::string colour = "#1f77b4";
  double width_px = 1.8;
  std::string dash;          // SVG stroke-dasharray, "" = solid
  double marker_px = 3.5;    // scatter: radius (half the size of other shapes)
  Marker marker = Marker::kDot;
  // Outline: under every marker but kDot, so that an open shape shows on
  // any background (a heat map's dark and light cells alike); around a
  // kDot, so that overlapping dots stay apart. "" = none (dots dense
  // enough to merge into a line would turn its colour pale).
  std::string halo = "#ffffff";
};

// Heat map options. Colours: continuous (viridis over the data range
// extended to round ticks) unless class_bounds is given; then a value v
// takes class_colours[k] for the number k of bounds <= v (so
// class_colours has one more entry than class_bounds), and the colour bar
// shows the classes as bands with the bounds as its ticks.
struct HeatOptions {
  std::string colour_label;                 // colour bar title, with unit
  std::vector<double> class_bounds;         // ascending
  std::vector<std::string> class_colours;   // class_bounds.size() + 1
  // printf format of a label written in each cell ("%.1f"), where the
  // label fits inside the cell; "" = none.
  std::string value_format;
  // Tooltip (SVG <title>) per cell, same layout as z; empty = none.
  std::vector<std::string> cell_titles;
};

namespace internal {
struct Render;   // the layout and drawing of one figure (plot/internal.h)
}  // namespace internal

class Figure {
 public:
  // id: unique within the page (letters, digits, '-').
  Figure(std::string id, double width_px, double height_px);

  void SetTitle(std::string t) { title_ = std::move(t); }
  // Axis labels carry their unit: "id [A]".
  void SetXLabel(std::string l) { xlabel_ = std::move(l); }
  void SetYLabel(std::string l) { ylabel_ = std::move(l); }
  // Fixed data ranges (still extended to whole ticks); otherwise the range
  // of everything added.
  void SetXRange(double lo, double hi) { xrange_ = {lo, hi}; }
  void SetYRange(double lo, double hi) { yrange_ = {lo, hi}; }
  // Same data units per pixel on both axes (circles look round).
  void SetEqualAspect(bool on) { equal_aspect_ = on; }
  // Frame exactly at the data (or fixed) range instead of out to whole
  // ticks: for views whose range is chosen by the caller, where a tick
  // step of 50 would otherwise add a band with nothing in it.
  void SetTight(bool x_on, bool y_on) { tight_x_ = x_on, tight_y_ = y_on; }
  // Logarithmic y axis, ticks on whole decades. The range runs from the
  // decade at or below the smallest positive value to the decade at or
  // above the largest (SetYRange overrides), but spans at most
  // `max_decades`: smaller values lie below the axis floor (bars mark them
  // there, lines break). Values <= 0 have no place on it and are skipped.
  void SetYLog(bool on, int max_decades = 6) { y_log_ = on, max_decades_ = max_decades; }
  // Legend in rows below the axes instead of a column on the right: for
  // long labels, or a plot whose width matters more than its height.
  void SetLegendBelow(bool on) { legend_below_ = on; }

  void Line(const std::vector<double>& x, const std::vector<double>& y, const Style& s, std::string label);
  // Markers (Style::marker); y_err (optional, same length) draws +-y_err bars.
  void Scatter(const std::vector<double>& x, const std::vector<double>& y, const Style& s, std::string label,
               const std::vector<double>& y_err = {});
  // Bars from the axis floor (y = 0, or the bottom of a log axis) to each
  // value, centred at x + offset, `width` wide (both in x units), filled
  // with the style's colour. A bar is cut at the frame: it never reaches
  // below the floor or above the top. A value under a log axis's floor
  // draws no bar but a down-pointing triangle on the floor (class
  // "below-floor"), so no value disappears unseen; the legend then gets an
  // entry for those triangles.
  void Bars(const std::vector<double>& x, const std::vector<double>& value, double width, const Style& s,
            std::string label, double offset = 0);
  // One contour line per level, each labelled on the line with its value
  // (format e.g. "%.0f"; "" = unlabelled); one legend entry for the set.
  void Contours(const std::vector<double>& xs, const std::vector<double>& ys, const std::vector<double>& z,
                const std::vector<double>& levels, const Style& s, std::string label,
                const std::string& level_format = "%g");
  // Heat map of z on the grid (cell edges midway between nodes), NaN cells
  // left blank; a colour bar titled `colour_label` (with unit) on the right,
  // with round ticks along its length.
  void Heatmap(const std::vector<double>& xs, const std::vector<double>& ys, const std::vector<double>& z,
               std::string colour_label);
  void Heatmap(const std::vector<double>& xs, const std::vector<double>& ys, const std::vector<double>& z,
               HeatOptions options);
  // A line of text in the legend without a mark: what the reader needs to
  // read the figure and no mark shows (e.g. why a curve is missing).
  void Note(std::string text);

  std::string Svg() const;
  // Number of legend entries added, notes included (tests and the
  // report's self-check); the entry for bars under a log axis's floor is
  // added when the floor is known, in Svg().
  size_t LegendEntries() const { return legend_.size(); }

 private:
  friend struct internal::Render;
  friend std::string PanelsSvg(const std::string&, const std::string&, const std::vector<Figure>&, int);
  struct Mark {
    enum Kind { kLine, kScatter, kContour, kLabel, kBars } kind;
    std::vector<double> x, y, err;
    Style style;
    std::string text;   // kLabel
    double width = 0, offset = 0;   // kBars
  };
  struct LegendEntry {
    enum Kind { kLine, kMarker, kSwatch, kNote } kind;
    std::string label;
    Style style;
  };
  struct Heat {
    std::vector<double> xs, ys, z;
    HeatOptions options;
    double lo = 0, hi = 1;   // range of the finite values
  };
  void Extend(double x, double y);
  // The figure's SVG element; `position` adds attributes (x, y) when it is
  // nested in a panel SVG.
  std::string Render(const std::string& position) const;

  std::string id_, title_, xlabel_, ylabel_;
  double width_px_, height_px_;
  std::optional<std::pair<double, double>> xrange_, yrange_;
  bool equal_aspect_ = false;
  bool tight_x_ = false, tight_y_ = false;
  bool y_log_ = false;
  int max_decades_ = 6;
  bool legend_below_ = false;
  double dx_lo_ = 0, dx_hi_ = 0, dy_lo_ = 0, dy_hi_ = 0;
  bool have_data_ = false;
  // Positive y values only: the range of a log axis.
  double pos_lo_ = 0, pos_hi_ = 0;
  bool have_pos_ = false;
  std::vector<Mark> marks_;
  std::vector<LegendEntry> legend_;
  std::optional<Heat> heat_;
};

// Several figures in one SVG, `columns` to a row (each cell as large as the
// largest figure), under a title that is wrapped to the width. Each figure
// keeps its own axes, legend and clip ids (give them distinct ids).
std::string PanelsSvg(const std::string& id, const std::string& title, const std::vector<Figure>& panels,
                      int columns = 2);

}  // namespace fluxcal::plot

#endif  // FLUXCAL_PLOT_PLOT_H_
