// A figure's content as it is added (marks, legend entries, data ranges,
// the heat map) and the SVG of one figure or of several side by side; the
// layout and the drawing are Render's (plot/internal.h).
#include <algorithm>
#include <cmath>

#include "plot/internal.h"
#include "plot/plot.h"

namespace fluxcal::plot {

using internal::Fmt;
using internal::Px;
using internal::Wrap;

Figure::Figure(std::string id, double width_px, double height_px)
    : id_(std::move(id)), width_px_(width_px), height_px_(height_px) {}

void Figure::Extend(double x, double y) {
  if (!std::isfinite(x) || !std::isfinite(y)) return;
  if (y > 0) {
    pos_lo_ = have_pos_ ? std::min(pos_lo_, y) : y;
    pos_hi_ = have_pos_ ? std::max(pos_hi_, y) : y;
    have_pos_ = true;
  }
  if (!have_data_) {
    dx_lo_ = dx_hi_ = x;
    dy_lo_ = dy_hi_ = y;
    have_data_ = true;
    return;
  }
  dx_lo_ = std::min(dx_lo_, x);
  dx_hi_ = std::max(dx_hi_, x);
  dy_lo_ = std::min(dy_lo_, y);
  dy_hi_ = std::max(dy_hi_, y);
}

void Figure::Line(const std::vector<double>& x, const std::vector<double>& y, const Style& s, std::string label) {
  for (size_t k = 0; k < std::min(x.size(), y.size()); ++k) Extend(x[k], y[k]);
  marks_.push_back({Mark::kLine, x, y, {}, s, ""});
  if (!label.empty()) legend_.push_back({LegendEntry::kLine, std::move(label), s});
}

void Figure::Scatter(const std::vector<double>& x, const std::vector<double>& y, const Style& s, std::string label,
                     const std::vector<double>& y_err) {
  for (size_t k = 0; k < std::min(x.size(), y.size()); ++k) {
    const double e = k < y_err.size() && std::isfinite(y_err[k]) ? y_err[k] : 0;
    Extend(x[k], y[k] - e);
    Extend(x[k], y[k] + e);
  }
  marks_.push_back({Mark::kScatter, x, y, y_err, s, ""});
  if (!label.empty()) legend_.push_back({LegendEntry::kMarker, std::move(label), s});
}

void Figure::Bars(const std::vector<double>& x, const std::vector<double>& value, double width, const Style& s,
                  std::string label, double offset) {
  for (size_t k = 0; k < std::min(x.size(), value.size()); ++k) {
    const double v = std::isfinite(value[k]) ? value[k] : 0;
    Extend(x[k] + offset - width / 2, v);
    Extend(x[k] + offset + width / 2, v);
    // A linear axis shows where the bars start.
    if (!y_log_) Extend(x[k] + offset, 0);
  }
  Mark m{Mark::kBars, x, value, {}, s, ""};
  m.width = width;
  m.offset = offset;
  marks_.push_back(std::move(m));
  if (!label.empty()) legend_.push_back({LegendEntry::kSwatch, std::move(label), s});
}

void Figure::Contours(const std::vector<double>& xs, const std::vector<double>& ys, const std::vector<double>& z,
                      const std::vector<double>& levels, const Style& s, std::string label,
                      const std::string& level_format) {
  for (double level : levels) {
    auto lines = ContourLines(xs, ys, z, level);
    const Polyline* longest = nullptr;
    for (const auto& l : lines) {
      std::vector<double> x, y;
      for (const auto& [a, b] : l) {
        x.push_back(a);
        y.push_back(b);
      }
      marks_.push_back({Mark::kContour, x, y, {}, s, ""});
      if (longest == nullptr || l.size() > longest->size()) longest = &l;
    }
    if (!level_format.empty() && longest != nullptr && longest->size() >= 2) {
      // The whole line goes with the label: where it sits is decided when
      // the visible range is known (the middle of the visible stretch).
      std::vector<double> x, y;
      for (const auto& [a, b] : *longest) {
        x.push_back(a);
        y.push_back(b);
      }
      marks_.push_back({Mark::kLabel, x, y, {}, s, Fmt(level_format.c_str(), level)});
    }
  }
  // The grid spans the field: it sets the range even where no level runs.
  if (!xs.empty() && !ys.empty()) {
    Extend(xs.front(), ys.front());
    Extend(xs.back(), ys.back());
  }
  if (!label.empty()) legend_.push_back({LegendEntry::kLine, std::move(label), s});
}

void Figure::Heatmap(const std::vector<double>& xs, const std::vector<double>& ys, const std::vector<double>& z,
                     std::string colour_label) {
  HeatOptions o;
  o.colour_label = std::move(colour_label);
  Heatmap(xs, ys, z, std::move(o));
}

void Figure::Heatmap(const std::vector<double>& xs, const std::vector<double>& ys, const std::vector<double>& z,
                     HeatOptions options) {
  Heat h{xs, ys, z, std::move(options), 0, 1};
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (double v : z) {
    if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  }
  if (!std::isfinite(lo)) lo = 0, hi = 1;
  // The data's range; the colour bar's (out to round ticks) is set when
  // the bar's length, and so its tick count, is known.
  h.lo = lo;
  h.hi = hi;
  // Classes need one colour more than bounds; anything else falls back to
  // the continuous map rather than index past the colours.
  if (h.options.class_colours.size() != h.options.class_bounds.size() + 1) {
    h.options.class_bounds.clear();
    h.options.class_colours.clear();
  }
  // Cell edges half a step beyond the outer nodes (a single node: a cell
  // one unit wide, as the drawing below takes it).
  auto first_edge = [](const std::vector<double>& v) { return v.size() >= 2 ? v[0] - (v[1] - v[0]) / 2 : v[0] - 0.5; };
  auto last_edge = [](const std::vector<double>& v) {
    return v.size() >= 2 ? v.back() + (v.back() - v[v.size() - 2]) / 2 : v.back() + 0.5;
  };
  if (!xs.empty() && !ys.empty()) {
    Extend(first_edge(xs), first_edge(ys));
    Extend(last_edge(xs), last_edge(ys));
  }
  heat_ = std::move(h);
}

void Figure::Note(std::string text) {
  if (!text.empty()) legend_.push_back({LegendEntry::kNote, std::move(text), Style{}});
}

std::string Figure::Svg() const { return Render(""); }

std::string Figure::Render(const std::string& position) const { return internal::Render(*this).Svg(position); }

std::string PanelsSvg(const std::string& id, const std::string& title, const std::vector<Figure>& panels,
                      int columns) {
  const size_t n = panels.size();
  const size_t cols = std::max<size_t>(1, std::min<size_t>(n == 0 ? 1 : n, static_cast<size_t>(std::max(1, columns))));
  const size_t rows = n == 0 ? 0 : (n + cols - 1) / cols;
  double cw = 0, ch = 0;
  for (const auto& f : panels) cw = std::max(cw, f.width_px_), ch = std::max(ch, f.height_px_);
  const double width = std::max(cw * cols, 200.0);
  const double title_font = 13, title_line = 17;
  const auto lines = title.empty() ? std::vector<std::string>{} : Wrap(title, width - 16, title_font);
  const double top = lines.empty() ? 0 : 8 + title_line * lines.size();
  const double height = top + ch * rows;
  std::string s = "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"panels\" id=\"" + Escape(id) + "\" width=\"" +
                  Px(width) + "\" height=\"" + Px(height) + "\" viewBox=\"0 0 " + Px(width) + " " + Px(height) +
                  "\" font-family=\"sans-serif\" font-size=\"11\">\n";
  s += "<rect width=\"" + Px(width) + "\" height=\"" + Px(height) + "\" fill=\"white\"/>\n";
  for (size_t k = 0; k < lines.size(); ++k) {
    s += "<text x=\"8\" y=\"" + Px(title_line * (k + 1)) + "\" font-size=\"" + Px(title_font) +
         "\" font-weight=\"bold\">" + Escape(lines[k]) + "</text>\n";
  }
  for (size_t k = 0; k < n; ++k) {
    const double x = cw * (k % cols), y = top + ch * (k / cols);
    s += panels[k].Render(" x=\"" + Px(x) + "\" y=\"" + Px(y) + "\"");
  }
  s += "</svg>\n";
  return s;
}

}  // namespace fluxcal::plot