// The SVG writer's own parts (not a public API; nothing outside plot/
// includes this): the text primitives every part writes with
// (svg_text.cc) and Render, one figure's layout (layout.cc) and its SVG
// written part by part (render.cc).
#ifndef FLUXCAL_PLOT_INTERNAL_H_
#define FLUXCAL_PLOT_INTERNAL_H_

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "plot/plot.h"

namespace fluxcal::plot::internal {

// ------------------------------------------------------------ svg_text.cc

std::string Fmt(const char* f, double v);   // printf of one number
std::string Px(double v);                    // a coordinate: one decimal
// Width of a label in px at font-size 11 sans-serif: a conservative average
// glyph width, so that margins computed from it never cut text.
double TextWidthPx(const std::string& s, double font_px = 11);
double Step(const std::vector<double>& t);   // a tick list's step
// One marker centred at (cx, cy): the shape, and for open shapes a wider
// outline in the halo colour under it (class "halo", so that counting
// class="point" counts markers).
std::string MarkerSvg(const Style& st, double cx, double cy, const std::string& cls);
// Greedy word wrap at `max_px` (the layout's glyph width): lines that fit,
// a single word longer than the width on a line of its own.
std::vector<std::string> Wrap(const std::string& text, double max_px, double font_px);
// Black or white, whichever reads on a "#rrggbb" fill.
std::string TextOn(const std::string& fill);

// ----------------------------------------------------- layout.cc, render.cc

// One figure's SVG: the constructor lays it out (layout.cc: ranges and
// ticks, margins, legend places, colour bar, plot area, in that order);
// Svg writes it part by part (render.cc).
struct Render {
  using Mark = Figure::Mark;
  using LegendEntry = Figure::LegendEntry;

  explicit Render(const Figure& f);
  // `position` adds attributes (x, y) when the figure is nested in a panel SVG.
  std::string Svg(const std::string& position) const;

  // Layout steps.
  void Ranges();            // data ranges, ticks (round steps or decades)
  void Margins();           // left and top from tick labels, axis labels, title
  void LegendLayout();      // the entries and where each goes; bottom margin
  void ColourBarLayout();   // the colour bar's ticks, scale and width
  void PlotArea();          // right margin, plot size, equal aspect
  std::vector<std::string> YLabels() const;

  // Writing steps, in the order they are drawn.
  double X(double x) const;   // data to px
  double Y(double y) const;   // NaN on a log axis for values <= 0
  std::string HeatColour(double v) const;
  std::string Open(const std::string& position) const;   // svg element, clip path, title, background
  std::string HeatCells() const;
  std::string Grid() const;
  std::string Marks() const;
  std::string ContourLabels() const;
  std::string Axes() const;   // frame, ticks, axis labels
  std::string ColourBar() const;
  std::string Legend() const;

  const Figure& fig;
  std::string clip;   // the clip path's id
  double font = 11;
  double xl = 0, xh = 1, yl = 0, yh = 1;   // the axes' ranges
  int want_x = 0, want_y = 0;              // tick counts asked for
  bool hug_x = false, hug_y = false;       // frame at the range, not out to whole ticks
  std::vector<double> xt, yt;
  std::vector<std::string> ylab, ytext;    // decade labels (log axis); the y tick labels
  double xlab_half = 0, left = 0, top = 0, base_bottom = 0, bottom = 0, right = 0, pw = 0, ph = 0;
  double title_font = 13, title_line = 16;
  std::vector<std::string> title_lines;
  std::vector<LegendEntry> legend;
  double entry_h = 17, legend_top = 0, legend_w = 0;
  std::vector<double> entry_w, col_w;
  size_t per_col = 1, below_rows = 0;
  std::vector<std::pair<double, size_t>> below_at;   // x from the left edge + 8, row
  double bar_w = 0;
  std::vector<double> bar_ticks;
  bool classes = false;
  double c_lo = 0, c_hi = 1;   // the colour scale
  double lyl = 0, lyh = 1;     // log10 of a log axis's range
};

}  // namespace fluxcal::plot::internal

#endif  // FLUXCAL_PLOT_INTERNAL_H_
