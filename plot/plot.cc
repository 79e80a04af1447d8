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

std::string FormatDecade(int exponent) {
  if (exponent >= -3 && exponent <= 4) {
    return FormatTick(std::pow(10.0, exponent), std::pow(10.0, std::min(exponent, 0)));
  }
  return Fmt("%.0e", std::pow(10.0, exponent));
}

std::vector<size_t> CoincidentGroups(const std::vector<std::vector<double>>& ys, double tol) {
  std::vector<size_t> group(ys.size());
  for (size_t k = 0; k < ys.size(); ++k) {
    group[k] = k;
    for (size_t l = 0; l < k; ++l) {
      if (group[l] != l || ys[l].size() != ys[k].size()) continue;   // compare with group leaders only
      bool same = true;
      for (size_t i = 0; i < ys[k].size() && same; ++i) {
        if (std::isfinite(ys[k][i]) && std::isfinite(ys[l][i])) same = std::abs(ys[k][i] - ys[l][i]) <= tol;
        else same = std::isfinite(ys[k][i]) == std::isfinite(ys[l][i]);
      }
      if (same) {
        group[k] = l;
        break;
      }
    }
  }
  return group;
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

namespace {

// One marker centred at (cx, cy): the shape, and for open shapes a wider
// outline in the halo colour under it (class "halo", so that counting
// class="point" counts markers).
std::string MarkerSvg(const Style& st, double cx, double cy, const std::string& cls) {
  const double r = st.marker_px;
  const std::string c = st.colour;
  auto shape = [&](const std::string& colour, double extra, bool main) {
    const std::string klass = main ? " class=\"" + cls + "\"" : " class=\"halo\"";
    const std::string sw = Px((main ? 1.6 : 1.6 + 2 * extra));
    switch (st.marker) {
      case Marker::kDot:
        return "<circle" + klass + " cx=\"" + Px(cx) + "\" cy=\"" + Px(cy) + "\" r=\"" + Px(r) + "\" fill=\"" + c +
               (st.halo.empty() ? std::string("\"") : "\" stroke=\"" + st.halo + "\" stroke-width=\"0.6\"") + "/>\n";
      case Marker::kRing:
        return "<circle" + klass + " cx=\"" + Px(cx) + "\" cy=\"" + Px(cy) + "\" r=\"" + Px(r) +
               "\" fill=\"none\" stroke=\"" + colour + "\" stroke-width=\"" + sw + "\"/>\n";
      case Marker::kCross:
        return "<path" + klass + " d=\"M" + Px(cx - r) + " " + Px(cy - r) + " L" + Px(cx + r) + " " + Px(cy + r) +
               " M" + Px(cx - r) + " " + Px(cy + r) + " L" + Px(cx + r) + " " + Px(cy - r) + "\" stroke=\"" +
               colour + "\" stroke-width=\"" + sw + "\" stroke-linecap=\"round\"/>\n";
      case Marker::kSquare:
        return "<rect" + klass + " x=\"" + Px(cx - r) + "\" y=\"" + Px(cy - r) + "\" width=\"" + Px(2 * r) +
               "\" height=\"" + Px(2 * r) + "\" fill=\"none\" stroke=\"" + colour + "\" stroke-width=\"" + sw +
               "\"/>\n";
      case Marker::kTriangleDown:
        return "<path" + klass + " d=\"M" + Px(cx - r) + " " + Px(cy - r) + " L" + Px(cx + r) + " " + Px(cy - r) +
               " L" + Px(cx) + " " + Px(cy + r) + " Z\" fill=\"" + (main ? colour : std::string("none")) +
               "\" stroke=\"" + colour + "\" stroke-width=\"" + (main ? std::string("0.8") : sw) +
               "\" stroke-linejoin=\"round\"/>\n";
    }
    return std::string();
  };
  std::string s;
  if (st.marker != Marker::kDot && !st.halo.empty()) s += shape(st.halo, 1.0, false);
  return s + shape(c, 0, true);
}

// Greedy word wrap at `max_px` (the layout's glyph width): lines that fit,
// a single word longer than the width on a line of its own.
std::vector<std::string> Wrap(const std::string& text, double max_px, double font_px) {
  std::vector<std::string> lines;
  std::string cur;
  size_t at = 0;
  while (at <= text.size()) {
    size_t sp = text.find(' ', at);
    if (sp == std::string::npos) sp = text.size();
    const std::string word = text.substr(at, sp - at);
    const std::string cand = cur.empty() ? word : cur + " " + word;
    if (!cur.empty() && TextWidthPx(cand, font_px) > max_px) {
      lines.push_back(cur);
      cur = word;
    } else {
      cur = cand;
    }
    at = sp + 1;
  }
  if (!cur.empty()) lines.push_back(cur);
  return lines;
}

// Black or white, whichever reads on a "#rrggbb" fill.
std::string TextOn(const std::string& fill) {
  unsigned r = 0, g = 0, b = 0;
  if (fill.size() == 7 && std::sscanf(fill.c_str() + 1, "%2x%2x%2x", &r, &g, &b) == 3) {
    return 0.299 * r + 0.587 * g + 0.114 * b < 140 ? "#fff" : "#000";
  }
  return "#000";
}

}  // namespace

std::string Figure::Svg() const { return Render(""); }

std::string Figure::Render(const std::string& position) const {
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
  std::vector<double> xt = NiceTicks(xl, xh, tx + (hug_x ? 2 : 0));
  std::vector<double> yt;
  std::vector<std::string> ylab;
  if (y_log_) {
    // Whole decades from the positive data (or the fixed range), at most
    // max_decades_ of them below the top.
    double lo = have_pos_ ? pos_lo_ : 1, hi = have_pos_ ? pos_hi_ : 10;
    if (yrange_ && yrange_->first > 0 && yrange_->second > yrange_->first) lo = yrange_->first, hi = yrange_->second;
    int e_hi = static_cast<int>(std::ceil(std::log10(hi) - 1e-9));
    int e_lo = static_cast<int>(std::floor(std::log10(lo) + 1e-9));
    if (e_hi <= e_lo) e_hi = e_lo + 1;
    e_lo = std::max(e_lo, e_hi - std::max(1, max_decades_));
    yl = std::pow(10.0, e_lo);
    yh = std::pow(10.0, e_hi);
    const int every = std::max(1, static_cast<int>(std::ceil((e_hi - e_lo) / static_cast<double>(ty + 2))));
    for (int e = e_lo; e <= e_hi; e += every) {
      yt.push_back(std::pow(10.0, e));
      ylab.push_back(FormatDecade(e));
    }
  } else {
    yt = NiceTicks(yl, yh, ty + (hug_y ? 2 : 0));
  }
  if (!heat_ && !tight_x_) xl = xt.front(), xh = xt.back();
  if (!heat_ && !tight_y_ && !y_log_) yl = yt.front(), yh = yt.back();
  auto ylabels = [&]() {
    if (y_log_) return ylab;
    std::vector<std::string> out;
    for (double v : yt) out.push_back(FormatTick(v, Step(yt)));
    return out;
  };
  // Margins from what has to fit: tick labels, axis labels, title, legend.
  double ylab_w = 0;
  for (const auto& l : ylabels()) ylab_w = std::max(ylab_w, TextWidthPx(l));
  // x tick labels are centred on their tick: the outermost ones reach
  // half their width past the frame, into the margins.
  double xlab_half = 0;
  for (double v : xt) xlab_half = std::max(xlab_half, TextWidthPx(FormatTick(v, Step(xt))) / 2);
  const double left = std::max(8 + (ylabel_.empty() ? 0 : 18) + ylab_w + 8, xlab_half + 4);
  const double title_font = 13, title_line = 16;
  const std::vector<std::string> title_lines =
      title_.empty() ? std::vector<std::string>{} : Wrap(title_, width_px_ - left - 8, title_font);
  const double top = title_lines.empty() ? 12 : 18 + title_line * (title_lines.size() - 1) + 12;
  const double base_bottom = 24 + (xlabel_.empty() ? 0 : 18);

  // Legend entries: those added, and for bars under a log axis's floor one
  // for their triangles (the floor is known only now).
  std::vector<LegendEntry> legend = legend_;
  if (y_log_) {
    for (const auto& m : marks_) {
      if (m.kind != Mark::kBars) continue;
      size_t below = 0;
      for (double v : m.y) below += std::isfinite(v) && v < yl * (1 - 1e-12);
      if (below == 0) continue;
      Style st = m.style;
      st.marker = Marker::kTriangleDown;
      st.marker_px = 3;
      st.halo.clear();
      legend.push_back({LegendEntry::kMarker, Fmt("%.0f", static_cast<double>(below)) + " below the axis floor " +
                                                  FormatDecade(static_cast<int>(std::lround(std::log10(yl)))) +
                                                  " (marked on it)", st});
    }
  }
  // Legend on the right in columns of as many entries as the height holds,
  // or below the axes in rows as wide as the figure.
  const double entry_h = 17, legend_top = top + 8;
  std::vector<double> entry_w;
  for (const auto& e : legend) {
    entry_w.push_back(e.kind == LegendEntry::kNote ? TextWidthPx(e.label) : 30 + TextWidthPx(e.label));
  }
  const size_t per_col =
      std::max<size_t>(1, static_cast<size_t>(std::floor((height_px_ - 8 - legend_top) / entry_h)) + 1);
  std::vector<double> col_w;
  std::vector<std::pair<double, size_t>> below_at;   // x from the left edge + 8, row
  size_t below_rows = 0;
  if (legend_below_) {
    double x = 0;
    size_t row = 0;
    for (double w : entry_w) {
      if (x > 0 && x + w > width_px_ - 16) ++row, x = 0;
      below_at.push_back({x, row});
      x += w + 18;
    }
    below_rows = legend.empty() ? 0 : row + 1;
  } else {
    for (size_t k = 0; k < legend.size(); ++k) {
      if (k % per_col == 0) col_w.push_back(0);
      col_w.back() = std::max(col_w.back(), entry_w[k]);
    }
  }
  double legend_w = 0;
  for (double w : col_w) legend_w += w + 12;
  const double bottom = base_bottom + (below_rows > 0 ? 6 + entry_h * below_rows : 0);
  double bar_w = 0;
  std::vector<double> bar_ticks;
  const bool classes = heat_ && !heat_->options.class_bounds.empty();
  // The colour scale runs from the bar's first to its last tick, so that
  // both ends are labelled and every label is a round number.
  double c_lo = 0, c_hi = 1;
  if (heat_) {
    bar_ticks = classes ? heat_->options.class_bounds : NiceTicks(heat_->lo, heat_->hi, ty);
    if (!classes) c_lo = bar_ticks.front(), c_hi = bar_ticks.back();
    double tw = 0;
    for (double v : bar_ticks) {
      tw = std::max(tw, TextWidthPx(classes ? Fmt("%g", v) : FormatTick(v, Step(bar_ticks))));
    }
    bar_w = 16 + 14 + 6 + tw + 22;   // gap, bar, tick, labels, rotated title
  }
  const double right = std::max(12 + bar_w + legend_w, xlab_half + 4);
  const double pw = std::max(40.0, width_px_ - left - right), ph = std::max(40.0, height_px_ - top - bottom);
  if (equal_aspect_ && !y_log_) {
    // Widen whichever axis has fewer units per pixel, at its end farther
    // from zero (a quadrant plot stays a quadrant plot); a range symmetric
    // about zero on both ends alike (a half plane stays centred).
    const double sx = (xh - xl) / pw, sy = (yh - yl) / ph;
    auto widen = [](double* lo, double* hi, double span) {
      const double extra = span - (*hi - *lo);
      if (std::abs(*hi + *lo) <= 1e-9 * (*hi - *lo)) {
        *hi += extra / 2;
        *lo -= extra / 2;
      } else if (std::abs(*hi) >= std::abs(*lo)) {
        *hi += extra;
      } else {
        *lo -= extra;
      }
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
  const std::vector<std::string> ytext = ylabels();
  auto X = [&](double x) { return left + (x - xl) / (xh - xl) * pw; };
  // Log axis: positions by decade; no position for values <= 0.
  const double lyl = y_log_ ? std::log10(yl) : 0, lyh = y_log_ ? std::log10(yh) : 1;
  auto Y = [&](double y) {
    if (y_log_) {
      if (!(y > 0)) return std::numeric_limits<double>::quiet_NaN();
      return top + ph - (std::log10(y) - lyl) / (lyh - lyl) * ph;
    }
    return top + ph - (y - yl) / (yh - yl) * ph;
  };
  auto inside = [](double v, double a, double b) { return v >= std::min(a, b) - 1e-9 * std::abs(b - a) &&
                                                          v <= std::max(a, b) + 1e-9 * std::abs(b - a); };

  std::string s = "<svg xmlns=\"http://www.w3.org/2000/svg\" class=\"figure\" id=\"" + Escape(id_) + "\"" + position +
                  " width=\"" + Px(width_px_) + "\" height=\"" + Px(height_px_) + "\" viewBox=\"0 0 " +
                  Px(width_px_) + " " + Px(height_px_) + "\" font-family=\"sans-serif\" font-size=\"" + Px(font) +
                  "\">\n";
  const std::string clip = id_ + "-clip";
  s += "<defs><clipPath id=\"" + clip + "\"><rect x=\"" + Px(left) + "\" y=\"" + Px(top) + "\" width=\"" + Px(pw) +
       "\" height=\"" + Px(ph) + "\"/></clipPath></defs>\n";
  for (size_t k = 0; k < title_lines.size(); ++k) {
    s += "<text x=\"" + Px(left) + "\" y=\"" + Px(18 + title_line * k) + "\" font-size=\"" + Px(title_font) +
         "\" font-weight=\"bold\">" + Escape(title_lines[k]) + "</text>\n";
  }
  s += "<rect x=\"" + Px(left) + "\" y=\"" + Px(top) + "\" width=\"" + Px(pw) + "\" height=\"" + Px(ph) +
       "\" fill=\"white\"/>\n";

  auto heat_colour = [&](double v) {
    const auto& o = heat_->options;
    if (!o.class_bounds.empty()) {
      size_t k = 0;
      while (k < o.class_bounds.size() && v >= o.class_bounds[k]) ++k;
      return o.class_colours[k];
    }
    return ColourMap((v - c_lo) / (c_hi - c_lo));
  };
  if (heat_) {
    const auto& h = *heat_;
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
        const std::string fill = heat_colour(v);
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
      const double base = y_log_ ? yl : std::clamp(0.0, std::min(yl, yh), std::max(yl, yh));
      for (size_t k = 0; k < std::min(m.x.size(), m.y.size()); ++k) {
        const double v = m.y[k];
        if (!std::isfinite(m.x[k]) || !std::isfinite(v)) continue;
        const double xc = m.x[k] + m.offset;
        const double xa = X(xc - m.width / 2), xb = X(xc + m.width / 2);
        if (y_log_ && v < yl * (1 - 1e-12)) {
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
  // Contour labels: kept clear of the frame (moved inwards) so none is cut,
  // and put where the other lines, markers and labels are farthest along
  // the visible stretch: a label crossed by a curve reads as neither.
  struct Seg { double x0, y0, x1, y1; size_t owner; };
  std::vector<Seg> segs;
  std::vector<std::pair<double, double>> dots;
  for (size_t o = 0; o < marks_.size(); ++o) {
    const auto& m = marks_[o];
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
    // The contour the label belongs to runs through it (its white outline
    // interrupts it); every other mark counts. (Found once per label: the
    // contour mark with the label's own points.)
    std::vector<bool> own(marks_.size(), false);
    for (size_t o = 0; o < marks_.size(); ++o) {
      own[o] = marks_[o].kind == Mark::kContour && marks_[o].x == m.x && marks_[o].y == m.y;
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
  // Frame and ticks.
  s += "<rect x=\"" + Px(left) + "\" y=\"" + Px(top) + "\" width=\"" + Px(pw) + "\" height=\"" + Px(ph) +
       "\" fill=\"none\" stroke=\"#333\"/>\n";
  s += "<g class=\"xticks\">\n";
  for (double v : xt) {
    if (!inside(v, xl, xh)) continue;
    s += "<line x1=\"" + Px(X(v)) + "\" y1=\"" + Px(top + ph) + "\" x2=\"" + Px(X(v)) + "\" y2=\"" + Px(top + ph + 4) +
         "\" stroke=\"#333\"/><text x=\"" + Px(X(v)) + "\" y=\"" + Px(top + ph + 16) + "\" text-anchor=\"middle\">" +
         FormatTick(v, Step(xt)) + "</text>\n";
  }
  s += "</g>\n<g class=\"yticks\">\n";
  for (size_t k = 0; k < yt.size(); ++k) {
    const double v = yt[k];
    if (!inside(v, yl, yh)) continue;
    s += "<line x1=\"" + Px(left - 4) + "\" y1=\"" + Px(Y(v)) + "\" x2=\"" + Px(left) + "\" y2=\"" + Px(Y(v)) +
         "\" stroke=\"#333\"/><text x=\"" + Px(left - 6) + "\" y=\"" + Px(Y(v) + 4) + "\" text-anchor=\"end\">" +
         ytext[k] + "</text>\n";
  }
  s += "</g>\n";
  if (!xlabel_.empty()) {
    s += "<text x=\"" + Px(left + pw / 2) + "\" y=\"" + Px(top + ph + 34) + "\" text-anchor=\"middle\">" +
         Escape(xlabel_) + "</text>\n";
  }
  if (!ylabel_.empty()) {
    const double yx = 8 + 10, yy = top + ph / 2;
    s += "<text x=\"" + Px(yx) + "\" y=\"" + Px(yy) + "\" text-anchor=\"middle\" transform=\"rotate(-90 " + Px(yx) +
         " " + Px(yy) + ")\">" + Escape(ylabel_) + "</text>\n";
  }
  // Colour bar: the continuous map with round ticks along its length, or
  // one band per class with the class bounds as ticks.
  double legend_x = left + pw + 12;
  if (heat_) {
    const double bx = left + pw + 16, bw = 14;
    s += "<g class=\"colourbar\">\n";
    if (classes) {
      const auto& colours = heat_->options.class_colours;
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
         " " + Px(ty) + ")\">" + Escape(heat_->options.colour_label) + "</text>\n</g>\n";
    legend_x = left + pw + bar_w + 12;
  }
  // Legend, outside the plot area so it never hides a mark.
  s += "<g class=\"legend\">\n";
  for (size_t k = 0; k < legend.size(); ++k) {
    const auto& e = legend[k];
    double lx = legend_x, ly = legend_top + entry_h * (k % per_col);
    if (legend_below_) {
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
