#include "plot/plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>

namespace fluxcal::plot {
namespace {

std::string Fmt(const char* f, double v) {
  char b[64];
  std::snprintf(b, sizeof b, f, v);
  return b;
}

std::string Px(double v) { return Fmt("%.1f", v); }


// Width of a label in px at font-size 11 sans-serif: a conservative average
// glyph width, so that margins computed from it never cut text.
double TextWidthPx(const std::string& s, double font_px = 11) { return 0.62 * font_px * s.size(); }

double Step(const std::vector<double>& t) { return t.size() > 1 ? t[1] - t[0] : 1.0; }

}  // namespace

std::string Escape(const std::string& s) {
  std::string o;
  for (char c : s) {
    switch (c) {
      case '&': o += "&amp;"; break;
      case '<': o += "&lt;"; break;
      case '>': o += "&gt;"; break;
      case '"': o += "&quot;"; break;
      default: o += c;
    }
  }
  return o;
}

std::vector<double> NiceTicks(double lo, double hi, int target) {
  if (!std::isfinite(lo) || !std::isfinite(hi)) lo = 0, hi = 1;
  if (lo > hi) std::swap(lo, hi);
  if (hi - lo < 1e-12 * std::max(1.0, std::abs(lo))) {
    const double pad = lo == 0 ? 1.0 : 0.5 * std::abs(lo);
    lo -= pad;
    hi += pad;
  }
  target = std::max(target, 2);
  // Among 1-2-5 steps around the raw step, the one whose tick count is
  // closest to the target (ties: the smaller step; a heat map shows only
  // the ticks inside its cells, so it needs the denser choice).
  const double raw = (hi - lo) / target;
  const double mag = std::pow(10.0, std::floor(std::log10(raw)));
  double step = mag;
  int best = std::numeric_limits<int>::max();
  for (double m : {0.5, 1.0, 2.0, 5.0, 10.0}) {
    const double st = m * mag;
    const int count = static_cast<int>(std::ceil(hi / st - 1e-9) - std::floor(lo / st + 1e-9)) + 1;
    if (std::abs(count - target) < best) {
      best = std::abs(count - target);
      step = st;
    }
  }
  // Small tolerance: a range that ends on a tick within rounding keeps it.
  const double eps = 1e-9 * step;
  const double first = std::floor((lo + eps) / step) * step;
  const double last = std::ceil((hi - eps) / step) * step;
  std::vector<double> t;
  for (int k = 0; first + k * step <= last + eps && k < 1000; ++k) {
    double v = first + k * step;
    if (std::abs(v) < 1e-9 * step) v = 0;   // no "-0" and no 1e-17 at zero
    t.push_back(v);
  }
  return t;
}

std::string FormatTick(double value, double step) {
  if (value == 0) return "0";
  const double a = std::abs(value);
  if (a >= 1e5 || a < 1e-3) return Fmt("%.3g", value);
  const int decimals = std::max(0, static_cast<int>(std::ceil(-std::log10(step) - 1e-9)));
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", decimals, value);
  return b;
}

std::vector<Polyline> ContourLines(const std::vector<double>& xs, const std::vector<double>& ys,
                                   const std::vector<double>& z, double level) {
  const size_t nx = xs.size(), ny = ys.size();
  std::vector<Polyline> out;
  if (nx < 2 || ny < 2 || z.size() != nx * ny) return out;
  using P = std::pair<double, double>;
  std::vector<std::pair<P, P>> segs;
  auto at = [&](size_t i, size_t j) { return z[j * nx + i]; };
  auto lerp = [&](double xa, double ya, double za, double xb, double yb, double zb) {
    const double t = za == zb ? 0.5 : (level - za) / (zb - za);
    return P{xa + t * (xb - xa), ya + t * (yb - ya)};
  };
  for (size_t j = 0; j + 1 < ny; ++j) {
    for (size_t i = 0; i + 1 < nx; ++i) {
      // Corners counter-clockwise from bottom-left.
      const double x0 = xs[i], x1 = xs[i + 1], y0 = ys[j], y1 = ys[j + 1];
      const double z0 = at(i, j), z1 = at(i + 1, j), z2 = at(i + 1, j + 1), z3 = at(i, j + 1);
      if (std::isnan(z0) || std::isnan(z1) || std::isnan(z2) || std::isnan(z3)) continue;
      const int c = (z0 >= level) | ((z1 >= level) << 1) | ((z2 >= level) << 2) | ((z3 >= level) << 3);
      if (c == 0 || c == 15) continue;
      // Each edge interpolated from its lower-index corner, so a crossing
      // shared by two cells is computed bit-identically from both (the
      // joining below relies on exact equality).
      const P b = lerp(x0, y0, z0, x1, y0, z1);   // bottom edge
      const P r = lerp(x1, y0, z1, x1, y1, z2);   // right
      const P t = lerp(x0, y1, z3, x1, y1, z2);   // top
      const P l = lerp(x0, y0, z0, x0, y1, z3);   // left
      const bool centre_high = (z0 + z1 + z2 + z3) / 4 >= level;
      switch (c) {
        case 1: case 14: segs.push_back({l, b}); break;
        case 2: case 13: segs.push_back({b, r}); break;
        case 3: case 12: segs.push_back({l, r}); break;
        case 4: case 11: segs.push_back({r, t}); break;
        case 6: case 9: segs.push_back({b, t}); break;
        case 7: case 8: segs.push_back({l, t}); break;
        case 5:   // z0 and z2 high
          if (centre_high) { segs.push_back({l, t}); segs.push_back({b, r}); }
          else { segs.push_back({l, b}); segs.push_back({r, t}); }
          break;
        case 10:  // z1 and z3 high
          if (centre_high) { segs.push_back({l, b}); segs.push_back({r, t}); }
          else { segs.push_back({l, t}); segs.push_back({b, r}); }
          break;
      }
    }
  }
  // Join segments that share an end point.
  std::multimap<P, size_t> by_end;
  for (size_t k = 0; k < segs.size(); ++k) {
    by_end.insert({segs[k].first, k});
    by_end.insert({segs[k].second, k});
  }
  std::vector<bool> used(segs.size(), false);
  auto take_next = [&](const P& p) -> std::optional<P> {
    auto range = by_end.equal_range(p);
    for (auto it = range.first; it != range.second; ++it) {
      const size_t k = it->second;
      if (used[k]) continue;
      used[k] = true;
      return segs[k].first == p ? segs[k].second : segs[k].first;
    }
    return std::nullopt;
  };
  for (size_t k = 0; k < segs.size(); ++k) {
    if (used[k]) continue;
    used[k] = true;
    Polyline line = {segs[k].first, segs[k].second};
    while (auto n = take_next(line.back())) line.push_back(*n);
    while (auto n = take_next(line.front())) line.insert(line.begin(), *n);
    out.push_back(std::move(line));
  }
  return out;
}

std::string ColourMap(double u) {
  // Viridis at nine anchors; linear between them.
  static const double kAnchors[9][3] = {{68, 1, 84},    {71, 44, 122},  {59, 81, 139},
                                        {44, 113, 142}, {33, 144, 141}, {39, 173, 129},
                                        {92, 200, 99},  {170, 220, 50}, {253, 231, 37}};
  if (!std::isfinite(u)) u = 0;
  u = std::clamp(u, 0.0, 1.0) * 8;
  const int k = std::min(7, static_cast<int>(u));
  const double f = u - k;
  char b[8];
  std::snprintf(b, sizeof b, "#%02x%02x%02x",
                static_cast<int>(std::lround(kAnchors[k][0] + f * (kAnchors[k + 1][0] - kAnchors[k][0]))),
                static_cast<int>(std::lround(kAnchors[k][1] + f * (kAnchors[k + 1][1] - kAnchors[k][1]))),
                static_cast<int>(std::lround(kAnchors[k][2] + f * (kAnchors[k + 1][2] - kAnchors[k][2]))));
  return b;
}

std::string Palette(int i) {
  static const char* kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e",
                                   "#8c564b", "#e377c2", "#17becf", "#7f7f7f", "#bcbd22"};
  return kColours[((i % 10) + 10) % 10];
}

Figure::Figure(std::string id, double width_px, double height_px)
    : id_(std::move(id)), width_px_(width_px), height_px_(height_px) {}

void Figure::Extend(double x, double y) {
  if (!std::isfinite(x) || !std::isfinite(y)) return;
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
  if (!label.empty()) legend_.push_back({std::move(label), s, false});
}

void Figure::Scatter(const std::vector<double>& x, const std::vector<double>& y, const Style& s, std::string label,
                     const std::vector<double>& y_err) {
  for (size_t k = 0; k < std::min(x.size(), y.size()); ++k) {
    const double e = k < y_err.size() && std::isfinite(y_err[k]) ? y_err[k] : 0;
    Extend(x[k], y[k] - e);
    Extend(x[k], y[k] + e);
  }
  marks_.push_back({Mark::kScatter, x, y, y_err, s, ""});
  if (!label.empty()) legend_.push_back({std::move(label), s, true});
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
  if (!label.empty()) legend_.push_back({std::move(label), s, false});
}

void Figure::Heatmap(const std::vector<double>& xs, const std::vector<double>& ys, const std::vector<double>& z,
                     std::string colour_label) {
  Heat h{xs, ys, z, std::move(colour_label), 0, 1};
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (double v : z) {
    if (std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
  }
  if (!std::isfinite(lo)) lo = 0, hi = 1;
  const auto t = NiceTicks(lo, hi, 6);
  h.lo = t.front();
  h.hi = t.back();
  // Cell edges half a step beyond the outer nodes.
  if (xs.size() >= 2 && ys.size() >= 2) {
    Extend(xs.front() - (xs[1] - xs[0]) / 2, ys.front() - (ys[1] - ys[0]) / 2);
    Extend(xs.back() + (xs.back() - xs[xs.size() - 2]) / 2, ys.back() + (ys.back() - ys[ys.size() - 2]) / 2);
  }
  heat_ = std::move(h);
}

std::string Figure::Svg() const {
  const double font = 11;
  // Ranges: given or from the data, then out to whole ticks. A heat map's
  // frame hugs its cells instead (ticks inside only), so no empty band;
  // so does a tight figure.
  auto range = [&](const std::optional<std::pair<double, double>>& fixed, double lo, double hi) {
    return fixed ? *fixed : std::pair<double, double>{lo, hi};
  };
  auto [xl, xh] = range(xrange_, have_data_ ? dx_lo_ : 0, have_data_ ? dx_hi_ : 1);
  auto [yl, yh] = range(yrange_, have_data_ ? dy_lo_ : 0, have_data_ ? dy_hi_ : 1);
  // Tick density from the figure's size (a label every ~90 px across,
  // ~60 px up), before the exact plot area is known.
  auto target = [](double px, double per) { return std::clamp(static_cast<int>(std::lround(px / per)), 3, 10); };
  const int tx = target(0.65 * width_px_, 90), ty = target(0.8 * height_px_, 60);
  // A frame that hugs its range shows only the ticks inside it: ask for
  // two more so that as many remain.
  const bool hug_x = heat_.has_value() || tight_x_, hug_y = heat_.has_value() || tight_y_;
  std::vector<double> xt = NiceTicks(xl, xh, tx + (hug_x ? 2 : 0)), yt = NiceTicks(yl, yh, ty + (hug_y ? 2 : 0));
  if (!heat_ && !tight_x_) xl = xt.front(), xh = xt.back();
  if (!heat_ && !tight_y_) yl = yt.front(), yh = yt.back();
  // Margins from what has to fit: tick labels, axis labels, title, legend.
  double ylab_w = 0;
  for (double v : yt) ylab_w = std::max(ylab_w, TextWidthPx(FormatTick(v, Step(yt))));
  const double left = 8 + (ylabel_.empty() ? 0 : 18) + ylab_w + 8;
  const double top = title_.empty() ? 12 : 30;
  const double bottom = 24 + (xlabel_.empty() ? 0 : 18);
  double legend_w = 0;
  for (const auto& e : legend_) legend_w = std::max(legend_w, 34 + TextWidthPx(e.label));
  double bar_w = 0;
  std::vector<double> bar_ticks;
  if (heat_) {
    bar_ticks = NiceTicks(heat_->lo, heat_->hi, ty);
    double tw = 0;
    for (double v : bar_ticks) tw = std::max(tw, TextWidthPx(FormatTick(v, Step(bar_ticks))));
    bar_w = 16 + 14 + 6 + tw + 22;   // gap, bar, tick, labels, rotated title
  }
  const double right = 12 + bar_w + (legend_w > 0 ? legend_w + 12 : 0);
  const double pw = std::max(40.0, width_px_ - left - right), ph = std::max(40.0, height_px_ - top - bottom);
  if (equal_aspect_) {
    // Widen whichever axis has fewer units per pixel, at its end farther
    // from zero (a quadrant plot stays a quadrant plot).
    const double sx = (xh - xl) / pw, sy = (yh - yl) / ph;
    auto widen = [](double* lo, double* hi, double span) {
      const double extra = span - (*hi - *lo);
      if (std::abs(*hi) >= std::abs(*lo)) *hi += extra; else *lo -= extra;
    };
    if (sx > sy) widen(&yl, &yh, sx * ph); else widen(&xl, &xh, sy * pw);
    xt = NiceTicks(xl, xh, target(pw, 80) + (hug_x ? 2 : 0));
    yt = NiceTicks(yl, yh, target(ph, 60) + (hug_y ? 2 : 0));
    // Same scale, same step: the finer of the two on both axes.
    const double step = std::min(Step(xt), Step(yt));
    auto with_step = [step](double lo, double hi) {
      std::vector<double> t;
      for (double v = std::floor(lo / step + 1e-9) * step; v <= hi + 1e-9 * step && t.size() < 200; v += step) {
        t.push_back(std::abs(v) < 1e-9 * step ? 0.0 : v);
      }
      return t;
    };
    xt = with_step(xl, xh);
    yt = with_step(yl, yh);
  }
  auto X = [&](double x) { return left + (x - xl) / (xh - xl) * pw; };
  auto Y = [&](double y) { return top + ph - (y - yl) / (yh - yl) * ph; };
  auto inside = [](double v, double a, double b) { return v >= std::min(a, b) - 1e-9 * std::abs(b - a) &&
                                                          v <= std::max(a, b) + 1e-9 * std::abs(b - a); };

  std::string s = "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"figure\" id=\"" + Escape(id_) + "\" width=\"" +
                  Px(width_px_) + "\" height=\"" + Px(height_px_) + "\" viewBox=\"0 0 " + Px(width_px_) + " " +
                  Px(height_px_) + "\" font-family=\"sans-serif\" font-size=\"" + Px(font) + "\">\n";
  const std::string clip = id_ + "-clip";
  s += "<defs><clipPath id=\"" + clip + "\"><rect x=\"" + Px(left) + "\" y=\"" + Px(top) + "\" width=\"" + Px(pw) +
       "\" height=\"" + Px(ph) + "\"/></clipPath></defs>\n";
  if (!title_.empty()) {
    s += "<text x=\"" + Px(left) + "\" y=\"18\" font-size=\"13\" font-weight=\"bold\">" + Escape(title_) + "</text>\n";
  }
  s += "<rect x=\"" + Px(left) + "\" y=\"" + Px(top) + "\" width=\"" + Px(pw) + "\" height=\"" + Px(ph) +
       "\" fill=\"white\"/>\n";

  if (heat_) {
    const auto& h = *heat_;
    const size_t nx = h.xs.size(), ny = h.ys.size();
    auto edge = [](const std::vector<double>& v, size_t k) {   // lower edge of cell k
      if (v.size() < 2) return v.empty() ? 0.0 : v[0] - 0.5;
      if (k == 0) return v[0] - (v[1] - v[0]) / 2;
      if (k == v.size()) return v.back() + (v.back() - v[v.size() - 2]) / 2;
      return (v[k - 1] + v[k]) / 2;
    };
    s += "<g clip-path=\"url(#" + clip + ")\" shape-rendering=\"crispEdges\">\n";
    for (size_t j = 0; j < ny; ++j) {
      for (size_t i = 0; i < nx; ++i) {
        const double v = h.z[j * nx + i];
        if (!std::isfinite(v)) continue;
        const double xa = X(edge(h.xs, i)), xb = X(edge(h.xs, i + 1));
        const double ya = Y(edge(h.ys, j + 1)), yb = Y(edge(h.ys, j));
        s += "<rect x=\"" + Px(std::min(xa, xb)) + "\" y=\"" + Px(std::min(ya, yb)) + "\" width=\"" +
             Px(std::abs(xb - xa) + 0.4) + "\" height=\"" + Px(std::abs(yb - ya) + 0.4) + "\" fill=\"" +
             ColourMap((v - h.lo) / (h.hi - h.lo)) + "\"/>\n";
      }
    }
    s += "</g>\n";
  }
  // Grid lines at the ticks, under the marks.
  s += "<g stroke=\"#e4e4e4\" stroke-width=\"1\">\n";
  for (double v : xt) {
    if (inside(v, xl, xh) && !heat_) s += "<line x1=\"" + Px(X(v)) + "\" y1=\"" + Px(top) + "\" x2=\"" + Px(X(v)) + "\" y2=\"" + Px(top + ph) + "\"/>\n";
  }
  for (double v : yt) {
    if (inside(v, yl, yh) && !heat_) s += "<line x1=\"" + Px(left) + "\" y1=\"" + Px(Y(v)) + "\" x2=\"" + Px(left + pw) + "\" y2=\"" + Px(Y(v)) + "\"/>\n";
  }
  s += "</g>\n";

  s += "<g clip-path=\"url(#" + clip + ")\">\n";
  for (const auto& m : marks_) {
    if (m.kind == Mark::kLine || m.kind == Mark::kContour) {
      // Non-finite samples break the line rather than join across them.
      std::string d;
      bool pen = false;
      for (size_t k = 0; k < std::min(m.x.size(), m.y.size()); ++k) {
        if (!std::isfinite(m.x[k]) || !std::isfinite(m.y[k])) {
          pen = false;
          continue;
        }
        d += (pen ? "L" : "M") + Px(X(m.x[k])) + " " + Px(Y(m.y[k])) + " ";
        pen = true;
      }
      if (d.empty()) continue;
      s += "<path d=\"" + d + "\" fill=\"none\" stroke=\"" + m.style.colour + "\" stroke-width=\"" +
           Px(m.style.width_px) + "\"" + (m.style.dash.empty() ? "" : " stroke-dasharray=\"" + m.style.dash + "\"") +
           " stroke-linejoin=\"round\"/>\n";
    } else if (m.kind == Mark::kScatter) {
      for (size_t k = 0; k < std::min(m.x.size(), m.y.size()); ++k) {
        if (!std::isfinite(m.x[k]) || !std::isfinite(m.y[k])) continue;
        const double cx = X(m.x[k]), cy = Y(m.y[k]);
        if (k < m.err.size() && std::isfinite(m.err[k]) && m.err[k] > 0) {
          s += "<line x1=\"" + Px(cx) + "\" y1=\"" + Px(Y(m.y[k] - m.err[k])) + "\" x2=\"" + Px(cx) + "\" y2=\"" +
               Px(Y(m.y[k] + m.err[k])) + "\" stroke=\"" + m.style.colour + "\" stroke-width=\"1\"/>\n";
        }
        s += "<circle cx=\"" + Px(cx) + "\" cy=\"" + Px(cy) + "\" r=\"" + Px(m.style.marker_px) + "\" fill=\"" +
             m.style.colour + "\" stroke=\"white\" stroke-width=\"0.6\"/>\n";
      }
    }
  }
  s += "</g>\n";
  // Contour labels: kept clear of the frame (moved inwards) so none is cut.
  for (const auto& m : marks_) {
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
    const size_t k = visible[visible.size() / 2];
    const double cx = X(m.x[k]), cy = Y(m.y[k]) + 3.5;
    s += "<text x=\"" + Px(cx) + "\" y=\"" + Px(cy) + "\" font-size=\"10\" text-anchor=\"middle\" fill=\"" +
         m.style.colour + "\" stroke=\"white\" stroke-width=\"3\" paint-order=\"stroke\">" + Escape(m.text) +
         "</text>\n";
  }
  // Frame and ticks.
  s += "<rect x=\"" + Px(left) + "\" y=\"" + Px(top) + "\" width=\"" + Px(pw) + "\" height=\"" + Px(ph) +
       "\" fill=\"none\" stroke=\"#333\"/>\n";
  for (double v : xt) {
    if (!inside(v, xl, xh)) continue;
    s += "<line x1=\"" + Px(X(v)) + "\" y1=\"" + Px(top + ph) + "\" x2=\"" + Px(X(v)) + "\" y2=\"" + Px(top + ph + 4) +
         "\" stroke=\"#333\"/><text x=\"" + Px(X(v)) + "\" y=\"" + Px(top + ph + 16) + "\" text-anchor=\"middle\">" +
         FormatTick(v, Step(xt)) + "</text>\n";
  }
  for (double v : yt) {
    if (!inside(v, yl, yh)) continue;
    s += "<line x1=\"" + Px(left - 4) + "\" y1=\"" + Px(Y(v)) + "\" x2=\"" + Px(left) + "\" y2=\"" + Px(Y(v)) +
         "\" stroke=\"#333\"/><text x=\"" + Px(left - 6) + "\" y=\"" + Px(Y(v) + 4) + "\" text-anchor=\"end\">" +
         FormatTick(v, Step(yt)) + "</text>\n";
  }
  if (!xlabel_.empty()) {
    s += "<text x=\"" + Px(left + pw / 2) + "\" y=\"" + Px(top + ph + 34) + "\" text-anchor=\"middle\">" +
         Escape(xlabel_) + "</text>\n";
  }
  if (!ylabel_.empty()) {
    const double yx = 8 + 10, yy = top + ph / 2;
    s += "<text x=\"" + Px(yx) + "\" y=\"" + Px(yy) + "\" text-anchor=\"middle\" transform=\"rotate(-90 " + Px(yx) +
         " " + Px(yy) + ")\">" + Escape(ylabel_) + "</text>\n";
  }
  // Colour bar with intermediate ticks.
  double legend_x = left + pw + 12;
  if (heat_) {
    const double bx = left + pw + 16, bw = 14;
    const int n = 64;
    for (int k = 0; k < n; ++k) {
      s += "<rect x=\"" + Px(bx) + "\" y=\"" + Px(top + ph - (k + 1) * ph / n) + "\" width=\"" + Px(bw) +
           "\" height=\"" + Px(ph / n + 0.5) + "\" fill=\"" + ColourMap((k + 0.5) / n) + "\"/>\n";
    }
    s += "<rect x=\"" + Px(bx) + "\" y=\"" + Px(top) + "\" width=\"" + Px(bw) + "\" height=\"" + Px(ph) +
         "\" fill=\"none\" stroke=\"#333\"/>\n";
    for (double v : bar_ticks) {
      const double y = top + ph - (v - heat_->lo) / (heat_->hi - heat_->lo) * ph;
      s += "<line x1=\"" + Px(bx + bw) + "\" y1=\"" + Px(y) + "\" x2=\"" + Px(bx + bw + 4) + "\" y2=\"" + Px(y) +
           "\" stroke=\"#333\"/><text x=\"" + Px(bx + bw + 6) + "\" y=\"" + Px(y + 4) + "\">" +
           FormatTick(v, Step(bar_ticks)) + "</text>\n";
    }
    const double tx = left + pw + bar_w - 4, ty = top + ph / 2;
    s += "<text x=\"" + Px(tx) + "\" y=\"" + Px(ty) + "\" text-anchor=\"middle\" transform=\"rotate(-90 " + Px(tx) +
         " " + Px(ty) + ")\">" + Escape(heat_->label) + "</text>\n";
    legend_x = left + pw + bar_w + 12;
  }
  // Legend, outside the plot area so it never hides a mark.
  double ly = top + 8;
  for (const auto& e : legend_) {
    if (e.dot) {
      s += "<circle cx=\"" + Px(legend_x + 11) + "\" cy=\"" + Px(ly) + "\" r=\"" + Px(e.style.marker_px) + "\" fill=\"" +
           e.style.colour + "\"/>\n";
    } else {
      s += "<line x1=\"" + Px(legend_x) + "\" y1=\"" + Px(ly) + "\" x2=\"" + Px(legend_x + 24) + "\" y2=\"" + Px(ly) +
           "\" stroke=\"" + e.style.colour + "\" stroke-width=\"" + Px(e.style.width_px) + "\"" +
           (e.style.dash.empty() ? "" : " stroke-dasharray=\"" + e.style.dash + "\"") + "/>\n";
    }
    s += "<text x=\"" + Px(legend_x + 30) + "\" y=\"" + Px(ly + 4) + "\">" + Escape(e.label) + "</text>\n";
    ly += 17;
  }
  s += "</svg>\n";
  return s;
}

}  // namespace fluxcal::plot
