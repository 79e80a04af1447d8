// A minimal SVG figure: one plot area with axes on round ("nice", 1-2-5)
// ticks, lines, scatter with error bars, contour lines of a gridded field
// (marching squares), a heat map with its colour bar, and a legend with an
// entry for every mark. No plotting dependency and nothing of fluxcal: the
// report (report/) and, in time, the fitting/tables/diagnosis plots build
// their figures from it.
//
// Layout rules the figure keeps so that a page of them reads at a glance:
//   - axis ranges are extended to whole tick steps, so the frame starts and
//     ends on a labelled tick;
//   - marks are clipped to the plot area; labels, colour bar and legend sit
//     outside it and inside the SVG's own width and height;
//   - every mark added with a non-empty label gets a legend entry.
// Ids inside the SVG (clip paths) are prefixed with the figure's id, so
// several figures can be inlined in one HTML document.
#ifndef FLUXCAL_PLOT_PLOT_H_
#define FLUXCAL_PLOT_PLOT_H_

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

// Marching squares over z sampled at (xs[i], ys[j]), z[j * xs.size() + i]
// (row-major, y slowest). Returns the level set z == level as polylines
// (segments joined where they meet). NaN cells are skipped; saddle cells are
// resolved by the cell's mean.
using Polyline = std::vector<std::pair<double, double>>;
std::vector<Polyline> ContourLines(const std::vector<double>& xs, const std::vector<double>& ys,
                                   const std::vector<double>& z, double level);

// Colour of u in [0, 1] on a perceptually ordered map (viridis anchors),
// as "#rrggbb".
std::string ColourMap(double u);
// The i-th of a set of distinct line colours (cycled).
std::string Palette(int i);
// Text escaped for XML / HTML content and attribute values (& < > ").
std::string Escape(const std::string& s);

struct Style {
  std::string colour = "#1f77b4";
  double width_px = 1.8;
  std::string dash;          // SVG stroke-dasharray, "" = solid
  double marker_px = 3.5;    // scatter: radius
};

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

  void Line(const std::vector<double>& x, const std::vector<double>& y, const Style& s, std::string label);
  // Dots; y_err (optional, same length) draws +-y_err bars.
  void Scatter(const std::vector<double>& x, const std::vector<double>& y, const Style& s, std::string label,
               const std::vector<double>& y_err = {});
  // One contour line per level, each labelled on the line with its value
  // (format e.g. "%.0f"; "" = unlabelled); one legend entry for the set.
  void Contours(const std::vector<double>& xs, const std::vector<double>& ys, const std::vector<double>& z,
                const std::vector<double>& levels, const Style& s, std::string label,
                const std::string& level_format = "%g");
  // Heat map of z on the grid (cell edges midway between nodes), NaN cells
  // left blank; a colour bar titled `colour_label` (with unit) on the right.
  void Heatmap(const std::vector<double>& xs, const std::vector<double>& ys, const std::vector<double>& z,
               std::string colour_label);

  std::string Svg() const;
  // Number of legend entries (tests and the report's self-check).
  size_t LegendEntries() const { return legend_.size(); }

 private:
  struct Mark {
    enum Kind { kLine, kScatter, kContour, kLabel } kind;
    std::vector<double> x, y, err;
    Style style;
    std::string text;   // kLabel
  };
  struct LegendEntry {
    std::string label;
    Style style;
    bool dot = false;
  };
  struct Heat {
    std::vector<double> xs, ys, z;
    std::string label;
    double lo = 0, hi = 1;
  };
  void Extend(double x, double y);

  std::string id_, title_, xlabel_, ylabel_;
  double width_px_, height_px_;
  std::optional<std::pair<double, double>> xrange_, yrange_;
  bool equal_aspect_ = false;
  bool tight_x_ = false, tight_y_ = false;
  double dx_lo_ = 0, dx_hi_ = 0, dy_lo_ = 0, dy_hi_ = 0;
  bool have_data_ = false;
  std::vector<Mark> marks_;
  std::vector<LegendEntry> legend_;
  std::optional<Heat> heat_;
};

}  // namespace fluxcal::plot

#endif  // FLUXCAL_PLOT_PLOT_H_
