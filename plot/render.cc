// One figure's SVG written part by part over its layout (layout.cc): the
// plot background, heat-map cells, grid, marks (lines, contours, scatter
// with error bars, bars), contour labels placed clear of the other marks,
// frame, ticks and axis labels, colour bar, legend.
#include <algorithm>
#include <cmath>
#include <limits>

#include "plot/internal.h"
#include "plot/plot.h"

namespace fluxcal::plot::internal {
namespace {

bool Inside(double v, double a, double b) {
  return v >= std::min(a, b) - 1e-9 * std::abs(b - a) &&
         v <= std::max(a, b) + 1e-9 * std::abs(b - a);
}

}  // namespace

std::string Render::Svg(const std::string& position) const {
  std::string s = Open(position);
  if (fig.heat_) s += HeatCells();
  s += Grid();
  s += Marks();
  s += ContourLabels();
  s += Axes();
  if (fig.heat_) s += ColourBar();
  s += Legend();
  return s;
}

double Render::X(double x) const { return left + (x - xl) / (xh - xl) * pw; }

double Render::Y(double y) const {
  if (fig.y_log_) {
    if (!(y > 0)) return std::numeric_limits<double>::quiet_NaN();
    return top + ph - (std::log10(y) - lyl) / (lyh - lyl) * ph;
  }
  return top + ph - (y - yl) / (yh - yl) * ph;
}

std::string Render::Open(const std::string& position) const {
  std::string s = "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"figure\" id=\"" + Escape(fig.id_) + "\"" + position +
                  " width=\"" + Px(fig.width_px_) + "\" height=\"" + Px(fig.height_px_) + "\" viewBox=\"0 0 " +
                  Px(fig.width_px_) + " " + Px(fig.height_px_) + "\" font-family=\"sans-serif\" font-size=\"" + Px(font) +
                  "\">\n";
  s += "<defs><clipPath id=\"" + clip + "\"><rect x=\"" + Px(left) + "\" y=\"" + Px(top) + "\" width=\"" + Px(pw) +
       "\" height=\"" + Px(ph) + "\"/></clipPath></defs>\n";
  for (size_t k = 0; k < title_lines.size(); ++k) {
    s += "<text x=\"" + Px(left) + "\" y=\"" + Px(18 + title_line * k) + "\" font-size=\"" + Px(title_font) +
         "\" font-weight=\"bold\">" + Escape(title_lines[k]) + "</text>\n";
  }
  s += "<rect x=\"" + Px(left) + "\" y=\"" + Px(top) + "\" width=\"" + Px(pw) + "\" height=\"" + Px(ph) +
       "\" fill=\"white\"/>\n";
  return s;
}

std::string Render::HeatColour(double v) const {
  const auto& o = fig.heat_->options;
  if (!o.class_bounds.empty()) {
    size_t k = 0;
    while (k < o.class_bounds.size() && v >= o.class_bounds[k]) ++k;
    return o.class_colours[k];
  }
  return ColourMap((v - c_lo) / (c_hi - c_lo));
}

std::string Render::HeatCells() const {
  std::string s;
  const auto& h = *fig.heat_;
  const size_t nx = h.xs.size(), ny = h.ys.size();
  auto edge = [](const std::vector<double>& v, size_t k) {   // lower edge of cell k
    if (v.size() < 2) return v.empty() ? 0.0 : v[0] - 0.5 + k;
    if (k == 0) return v[0] - (v[1] - v[0]) / 2;
    if (k == v.size()) return v.back() + (v.back() - v[v.size() - 2]) / 2;
    return (v[k - 1] + v[k]) / 2;
  };
  std::string labels;
  s += "<g clip-path=\"url(#" + clip + ")\" shape-rendering=\"crispEdges\">\n";
  for (size_t j = 0; j < ny; ++j) {
    for (size_t i = 0; i < nx; ++i) {
      if (j * nx + i >= h.z.size()) break;
      const double v = h.z[j * nx + i];
      if (!std::isfinite(v)) continue;
      const double xa = X(edge(h.xs, i)), xb = X(edge(h.xs, i + 1));
      const double ya = Y(edge(h.ys, j + 1)), yb = Y(edge(h.ys, j));
      const std::string fill = HeatColour(v);
      const std::string title = j * nx + i < h.options.cell_titles.size() ? h.options.cell_titles[j * nx + i] : "";
      s += "<rect class=\"cell\" x=\"" + Px(std::min(xa, xb)) + "\" y=\"" + Px(std::min(ya, yb)) + "\" width=\"" +
           Px(std::abs(xb - xa) + 0.4) + "\" height=\"" + Px(std::abs(yb - ya) + 0.4) + "\" fill=\"" + fill + "\"" +
           // Class cells are discrete points: a white edge keeps
           // neighbours of one class apart.
           (classes ? " stroke=\"#ffffff\" stroke-width=\"1\"" : "") +
           (title.empty() ? "/>\n" : "><title>" + Escape(title) + "</title></rect>\n");
      if (!h.options.value_format.empty()) {
        const std::string text = Fmt(h.options.value_format.c_str(), v);
        const double cx = (xa + xb) / 2, cy = (ya + yb) / 2;
        // Only where the label fits, and only with its centre in the view.
        if (TextWidthPx(text, 10) + 2 <= std::abs(xb - xa) && std::abs(yb - ya) >= 12 &&
            cx - TextWidthPx(text, 10) / 2 >= left && cx + TextWidthPx(text, 10) / 2 <= left + pw &&
            cy - 5 >= top && cy + 5 <= top + ph) {
          labels += "<text class=\"cell-label\" x=\"" + Px(cx) + "\" y=\"" + Px(cy + 3.5) +
                    "\" font-size=\"10\" text-anchor=\"middle\" fill=\"" + TextOn(fill) + "\">" + Escape(text) +
                    "</text>\n";
        }
      }
    }
  }
  s += "</g>\n" + labels;
  return s;
}

std::string Render::Grid() const {
  std::string s;
  // Grid lines at the ticks, under the marks.
  s += "<g stroke=\"#e4e4e4\" stroke-width=\"1\">\n";
  for (double v : xt) {
    if (Inside(v, xl, xh) && !fig.heat_) s += "<line x1=\"" + Px(X(v)) + "\" y1=\"" + Px(top) + "\" x2=\"" + Px(X(v)) + "\" y2=\"" + Px(top + ph) + "\"/>\n";
  }
  for (double v : yt) {
    if (Inside(v, yl, yh) && !fig.heat_) s += "<line x1=\"" + Px(left) + "\" y1=\"" + Px(Y(v)) + "\" x2=\"" + Px(left + pw) + "\" y2=\"" + Px(Y(v)) + "\"/>\n";
  }
  s += "</g>\n";
  return s;
}

std::string Render::Marks() const {
  std::string s;
  s += "<g clip-path=\"url(#" + clip + ")\">\n";
  for (const auto& m : fig.marks_) {
    if (m.kind == Mark::kLine || m.kind == Mark::kContour) {
      // Non-finite samples (and, on a log axis, values <= 0) break the line
      // rather than join across them.
      std::string d;
      bool pen = false;
      for (size_t k = 0; k < std::min(m.x.size(), m.y.size()); ++k) {
        const double py = Y(m.y[k]);
        if (!std::isfinite(m.x[k]) || !std::isfinite(m.y[k]) || !std::isfinite(py)) {
          pen = false;
          continue;
        }
        d += (pen ? "L" : "M") + Px(X(m.x[k])) + " " + Px(py) + " ";
        pen = true;
      }
      if (d.empty()) continue;
      s += std::string("<path class=\"") + (m.kind == Mark::kLine ? "line" : "contour") + "\" d=\"" + d +
           "\" fill=\"none\" stroke=\"" + m.style.colour + "\" stroke-width=\"" + Px(m.style.width_px) + "\"" +
           (m.style.dash.empty() ? "" : " stroke-dasharray=\"" + m.style.dash + "\"") +
           " stroke-linejoin=\"round\"/>\n";
    } else if (m.kind == Mark::kScatter) {
      for (size_t k = 0; k < std::min(m.x.size(), m.y.size()); ++k) {
        if (!std::isfinite(m.x[k]) || !std::isfinite(m.y[k]) || !std::isfinite(Y(m.y[k]))) continue;
        const double cx = X(m.x[k]), cy = Y(m.y[k]);
        if (k < m.err.size() && std::isfinite(m.err[k]) && m.err[k] > 0) {
          // On a log axis the lower end may be <= 0: the bar runs to the floor.
          const double lo_px = std::isfinite(Y(m.y[k] - m.err[k])) ? Y(m.y[k] - m.err[k]) : top + ph;
          s += "<line class=\"error\" x1=\"" + Px(cx) + "\" y1=\"" + Px(lo_px) + "\" x2=\"" + Px(cx) + "\" y2=\"" +
               Px(Y(m.y[k] + m.err[k])) + "\" stroke=\"" + m.style.colour + "\" stroke-width=\"1\"/>\n";
        }
        s += MarkerSvg(m.style, cx, cy, "point");
      }
    } else if (m.kind == Mark::kBars) {
      const double base = fig.y_log_ ? yl : std::clamp(0.0, std::min(yl, yh), std::max(yl, yh));
      for (size_t k = 0; k < std::min(m.x.size(), m.y.size()); ++k) {
        const double v = m.y[k];
        if (!std::isfinite(m.x[k]) || !std::isfinite(v)) continue;
        const double xc = m.x[k] + m.offset;
        const double xa = X(xc - m.width / 2), xb = X(xc + m.width / 2);
        if (fig.y_log_ && v < yl * (1 - 1e-12)) {
          Style tri = m.style;
          tri.marker = Marker::kTriangleDown;
          tri.marker_px = std::clamp(std::abs(xb - xa) / 2, 2.0, 3.5);
          tri.halo.clear();
          s += MarkerSvg(tri, (xa + xb) / 2, top + ph - tri.marker_px, "below-floor");
          continue;
        }
        // Both ends inside the frame: a bar never reaches below the floor
        // nor above the top, whatever the clip path does.
        const double y_end = std::clamp(Y(std::clamp(v, std::min(yl, yh), std::max(yl, yh))), top, top + ph);
        const double y_base = std::clamp(Y(base), top, top + ph);
        s += "<rect class=\"bar\" x=\"" + Px(std::min(xa, xb)) + "\" y=\"" + Px(std::min(y_end, y_base)) +
             "\" width=\"" + Px(std::max(0.6, std::abs(xb - xa))) + "\" height=\"" + Px(std::abs(y_base - y_end)) +
             "\" fill=\"" + m.style.colour + "\"/>\n";
      }
    }
  }
  s += "</g>\n";
  return s;
}

std::string Render::ContourLabels() const {
  std::string s;
  // Contour labels: kept clear of the frame (moved inwards) so none is cut,
  // and put where the other lines, markers and labels are farthest along
  // the visible stretch: a label crossed by a curve reads as neither.
  struct Seg { double x0, y0, x1, y1; size_t owner; };
  std::vector<Seg> segs;
  std::vector<std::pair<double, double>> dots;
  for (size_t o = 0; o < fig.marks_.size(); ++o) {
    const auto& m = fig.marks_[o];
    if (m.kind == Mark::kLine || m.kind == Mark::kContour) {
      for (size_t k = 1; k < std::min(m.x.size(), m.y.size()); ++k) {
        const double x0 = X(m.x[k - 1]), y0 = Y(m.y[k - 1]), x1 = X(m.x[k]), y1 = Y(m.y[k]);
        if (!std::isfinite(x0) || !std::isfinite(y0) || !std::isfinite(x1) || !std::isfinite(y1)) continue;
        if (std::max(x0, x1) < left || std::min(x0, x1) > left + pw || std::max(y0, y1) < top ||
            std::min(y0, y1) > top + ph) {
          continue;
        }
        segs.push_back({x0, y0, x1, y1, o});
      }
    } else if (m.kind == Mark::kScatter) {
      for (size_t k = 0; k < std::min(m.x.size(), m.y.size()); ++k) {
        if (std::isfinite(X(m.x[k])) && std::isfinite(Y(m.y[k]))) dots.push_back({X(m.x[k]), Y(m.y[k])});
      }
    }
  }
  auto seg_dist = [](const Seg& g, double px, double py) {
    const double dx = g.x1 - g.x0, dy = g.y1 - g.y0, len2 = dx * dx + dy * dy;
    const double t = len2 > 0 ? std::clamp(((px - g.x0) * dx + (py - g.y0) * dy) / len2, 0.0, 1.0) : 0.0;
    return std::hypot(px - g.x0 - t * dx, py - g.y0 - t * dy);
  };
  struct Placed { double x, y, w; };
  std::vector<Placed> placed;
  for (const auto& m : fig.marks_) {
    if (m.kind != Mark::kLabel) continue;
    const double w = TextWidthPx(m.text, 10);
    std::vector<size_t> visible;
    for (size_t k = 0; k < m.x.size(); ++k) {
      if (X(m.x[k]) > left + w / 2 + 2 && X(m.x[k]) < left + pw - w / 2 - 2 && Y(m.y[k]) > top + 12 &&
          Y(m.y[k]) < top + ph - 6) {
        visible.push_back(k);
      }
    }
    if (visible.empty()) continue;   // the line is outside the view: no label
    // The contour the label belongs to runs through it (its white outline
    // interrupts it); every other mark counts. (Found once per label: the
    // contour mark with the label's own points.)
    std::vector<bool> own(fig.marks_.size(), false);
    for (size_t o = 0; o < fig.marks_.size(); ++o) {
      own[o] = fig.marks_[o].kind == Mark::kContour && fig.marks_[o].x == m.x && fig.marks_[o].y == m.y;
    }
    size_t best = visible[visible.size() / 2];
    double best_score = -std::numeric_limits<double>::infinity();
    const double mid = visible.size() / 2.0;
    // At most about 60 candidate places along the line (a long contour has
    // hundreds of vertices a few pixels apart).
    const size_t stride = std::max<size_t>(1, visible.size() / 60);
    for (size_t c = 0; c < visible.size(); c += stride) {
      const double px = X(m.x[visible[c]]), py = Y(m.y[visible[c]]);
      double clear = std::numeric_limits<double>::infinity();
      for (const auto& g : segs) {
        if (own[g.owner]) continue;
        clear = std::min(clear, seg_dist(g, px, py) - w / 2);
        if (clear < best_score) break;   // its score (<= clear) cannot win any more
      }
      for (const auto& [dx, dy] : dots) clear = std::min(clear, std::hypot(px - dx, py - dy) - w / 2 - 3);
      for (const auto& p : placed) clear = std::min(clear, std::hypot(px - p.x, py - p.y) - (w + p.w) / 2);
      // Clearance counts up to a comfortable 12 px; beyond that, nearer
      // the middle of the visible stretch is better.
      const double score = std::min(clear, 12.0) - 0.01 * std::abs(c - mid);
      if (score > best_score) best_score = score, best = visible[c];
    }
    const double cx = X(m.x[best]), cy = Y(m.y[best]) + 3.5;
    placed.push_back({cx, cy - 3.5, w});
    s += "<text x=\"" + Px(cx) + "\" y=\"" + Px(cy) + "\" font-size=\"10\" text-anchor=\"middle\" fill=\"" +
         m.style.colour + "\" stroke=\"white\" stroke-width=\"3\" paint-order=\"stroke\">" + Escape(m.text) +
         "</text>\n";
  }
  return s;
}

std::string Render::Axes() const {
  std::string s;
  // Frame and ticks.
  s += "<rect x=\"" + Px(left) + "\" y=\"" + Px(top) + "\" width=\"" + Px(pw) + "\" height=\"" + Px(ph) +
       "\" fill=\"none\" stroke=\"#333\"/>\n";
  s += "<g class=\"xticks\">\n";
  for (double v : xt) {
    if (!Inside(v, xl, xh)) continue;
    s += "<line x1=\"" + Px(X(v)) + "\" y1=\"" + Px(top + ph) + "\" x2=\"" + Px(X(v)) + "\" y2=\"" + Px(top + ph + 4) +
         "\" stroke=\"#333\"/><text x=\"" + Px(X(v)) + "\" y=\"" + Px(top + ph + 16) + "\" text-anchor=\"middle\">" +
         FormatTick(v, Step(xt)) + "</text>\n";
  }
  s += "</g>\n<g class=\"yticks\">\n";
  for (size_t k = 0; k < yt.size(); ++k) {
    const double v = yt[k];
    if (!Inside(v, yl, yh)) continue;
    s += "<line x1=\"" + Px(left - 4) + "\" y1=\"" + Px(Y(v)) + "\" x2=\"" + Px(left) + "\" y2=\"" + Px(Y(v)) +
         "\" stroke=\"#333\"/><text x=\"" + Px(left - 6) + "\" y=\"" + Px(Y(v) + 4) + "\" text-anchor=\"end\">" +
         ytext[k] + "</text>\n";
  }
  s += "</g>\n";
  if (!fig.xlabel_.empty()) {
    s += "<text x=\"" + Px(left + pw / 2) + "\" y=\"" + Px(top + ph + 34) + "\" text-anchor=\"middle\">" +
         Escape(fig.xlabel_) + "</text>\n";
  }
  if (!fig.ylabel_.empty()) {
    const double yx = 8 + 10, yy = top + ph / 2;
    s += "<text x=\"" + Px(yx) + "\" y=\"" + Px(yy) + "\" text-anchor=\"middle\" transform=\"rotate(-90 " + Px(yx) +
         " " + Px(yy) + ")\">" + Escape(fig.ylabel_) + "</text>\n";
  }
  return s;
}

std::string Render::ColourBar() const {
  std::string s;
  // Colour bar: the continuous map with round ticks along its length, or
  // one band per class with the class bounds as ticks.
  const double bx = left + pw + 16, bw = 14;
  s += "<g class=\"colourbar\">\n";
  if (classes) {
    const auto& colours = fig.heat_->options.class_colours;
    const double band = ph / colours.size();
    for (size_t k = 0; k < colours.size(); ++k) {
      s += "<rect x=\"" + Px(bx) + "\" y=\"" + Px(top + ph - (k + 1) * band) + "\" width=\"" + Px(bw) +
           "\" height=\"" + Px(band) + "\" fill=\"" + colours[k] + "\"/>\n";
    }
    for (size_t k = 0; k < bar_ticks.size(); ++k) {
      const double y = top + ph - (k + 1) * band;
      s += "<line x1=\"" + Px(bx + bw) + "\" y1=\"" + Px(y) + "\" x2=\"" + Px(bx + bw + 4) + "\" y2=\"" + Px(y) +
           "\" stroke=\"#333\"/><text x=\"" + Px(bx + bw + 6) + "\" y=\"" + Px(y + 4) + "\">" +
           Fmt("%g", bar_ticks[k]) + "</text>\n";
    }
  } else {
    const int n = 64;
    for (int k = 0; k < n; ++k) {
      s += "<rect x=\"" + Px(bx) + "\" y=\"" + Px(top + ph - (k + 1) * ph / n) + "\" width=\"" + Px(bw) +
           "\" height=\"" + Px(ph / n + 0.5) + "\" fill=\"" + ColourMap((k + 0.5) / n) + "\"/>\n";
    }
    for (double v : bar_ticks) {
      const double y = top + ph - (v - c_lo) / (c_hi - c_lo) * ph;
      s += "<line x1=\"" + Px(bx + bw) + "\" y1=\"" + Px(y) + "\" x2=\"" + Px(bx + bw + 4) + "\" y2=\"" + Px(y) +
           "\" stroke=\"#333\"/><text x=\"" + Px(bx + bw + 6) + "\" y=\"" + Px(y + 4) + "\">" +
           FormatTick(v, Step(bar_ticks)) + "</text>\n";
    }
  }
  s += "<rect x=\"" + Px(bx) + "\" y=\"" + Px(top) + "\" width=\"" + Px(bw) + "\" height=\"" + Px(ph) +
       "\" fill=\"none\" stroke=\"#333\"/>\n";
  const double tx = left + pw + bar_w - 4, ty = top + ph / 2;
  s += "<text x=\"" + Px(tx) + "\" y=\"" + Px(ty) + "\" text-anchor=\"middle\" transform=\"rotate(-90 " + Px(tx) +
       " " + Px(ty) + ")\">" + Escape(fig.heat_->options.colour_label) + "</text>\n</g>\n";
  return s;
}

std::string Render::Legend() const {
  std::string s;
  // Beside the plot area, right of the colour bar if there is one.
  const double legend_x = fig.heat_ ? left + pw + bar_w + 12 : left + pw + 12;
  // Legend, outside the plot area so it never hides a mark.
  s += "<g class=\"legend\">\n";
  for (size_t k = 0; k < legend.size(); ++k) {
    const auto& e = legend[k];
    double lx = legend_x, ly = legend_top + entry_h * (k % per_col);
    if (fig.legend_below_) {
      lx = 8 + below_at[k].first;
      ly = top + ph + base_bottom + 12 + entry_h * below_at[k].second;
    } else {
      for (size_t c = 0; c < k / per_col; ++c) lx += col_w[c] + 12;
    }
    switch (e.kind) {
      case LegendEntry::kMarker:
        s += MarkerSvg(e.style, lx + 11, ly, "key");
        break;
      case LegendEntry::kLine:
        s += "<line x1=\"" + Px(lx) + "\" y1=\"" + Px(ly) + "\" x2=\"" + Px(lx + 24) + "\" y2=\"" + Px(ly) +
             "\" stroke=\"" + e.style.colour + "\" stroke-width=\"" + Px(e.style.width_px) + "\"" +
             (e.style.dash.empty() ? "" : " stroke-dasharray=\"" + e.style.dash + "\"") + "/>\n";
        break;
      case LegendEntry::kSwatch:
        s += "<rect x=\"" + Px(lx + 5) + "\" y=\"" + Px(ly - 5) + "\" width=\"14\" height=\"10\" fill=\"" +
             e.style.colour + "\"/>\n";
        break;
      case LegendEntry::kNote:
        break;
    }
    const double text_x = e.kind == LegendEntry::kNote ? lx : lx + 30;
    s += "<text x=\"" + Px(text_x) + "\" y=\"" + Px(ly + 4) + "\"" +
         (e.kind == LegendEntry::kNote ? " fill=\"#444\"" : "") + ">" + Escape(e.label) + "</text>\n";
  }
  s += "</g>\n</svg>\n";
  return s;
}

}  // namespace fluxcal::plot::internal
