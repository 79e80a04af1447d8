#include "fitting/plot.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace fluxcal::fit {
namespace {

constexpr const char* kColours[] = {"#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e",
                                    "#8c564b", "#e377c2", "#17becf", "#7f7f7f", "#bcbd22"};

// Distinct values, merged when closer than `tol` (operating points are held
// to a reference with a little control error).
std::vector<double> Levels(std::vector<double> v, double tol) {
  std::sort(v.begin(), v.end());
  std::vector<double> out;
  for (double x : v) {
    if (out.empty() || x - out.back() > tol) out.push_back(x);
  }
  return out;
}

struct Panel {
  double x0, y0, w, h;          // pixel frame
  double xlo, xhi, ylo, yhi;    // data range
  double X(double x) const { return x0 + (x - xlo) / (xhi - xlo) * w; }
  double Y(double y) const { return y0 + h - (y - ylo) / (yhi - ylo) * h; }
};

std::string Frame(const Panel& p, const std::string& xlabel, const std::string& ylabel) {
  std::string s = absl::StrFormat(
      "<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"white\" stroke=\"black\"/>\n", p.x0, p.y0,
      p.w, p.h);
  for (int k = 0; k <= 4; ++k) {
    const double x = p.xlo + (p.xhi - p.xlo) * k / 4, y = p.ylo + (p.yhi - p.ylo) * k / 4;
    s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%.0f</text>\n", p.X(x), p.y0 + p.h + 14, x);
    s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\">%.3f</text>\n", p.x0 - 4, p.Y(y) + 4,
                         y * 1e3);
  }
  s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%s</text>\n", p.x0 + p.w / 2,
                       p.y0 + p.h + 30, xlabel);
  s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\">%s</text>\n", p.x0, p.y0 - 6, ylabel);
  return s;
}

}  // namespace

std::string PlotFitSvg(const Calibration& cal, const FitData& data) {
  const auto& obs = data.inductances;
  double id_lo = 0, id_hi = 0, iq_hi = 1;
  double d_lo = 1e9, d_hi = 0, q_lo = 1e9, q_hi = 0;   // Ldd, Lqq ranges
  std::vector<double> ids, iqs;
  for (const auto& o : obs) {
    id_lo = std::min(id_lo, o.id_a);
    id_hi = std::max(id_hi, o.id_a);
    iq_hi = std::max(iq_hi, std::abs(o.iq_a));
    d_lo = std::min(d_lo, o.ldd_h - o.ldd_h_std);
    d_hi = std::max(d_hi, o.ldd_h + o.ldd_h_std);
    q_lo = std::min(q_lo, o.lqq_h - o.lqq_h_std);
    q_hi = std::max(q_hi, o.lqq_h + o.lqq_h_std);
    ids.push_back(o.id_a);
    iqs.push_back(std::abs(o.iq_a));
  }
  const double span = std::max(1.0, id_hi - id_lo);
  id_lo -= 0.1 * span;
  id_hi += 0.05 * span;
  iq_hi *= 1.1;
  const double tol = 0.03 * std::max(span, iq_hi);
  const auto iq_levels = Levels(iqs, tol), id_levels = Levels(ids, tol);
  // Curves first, so the range covers them too.
  struct Curve { std::vector<std::pair<double, double>> pts; std::vector<bool> extrapolated; };
  auto sample = [&](bool ldd, double level) {
    Curve c;
    for (int k = 0; k <= 80; ++k) {
      const double x = ldd ? id_lo + (id_hi - id_lo) * k / 80 : iq_hi * k / 80;
      const double id = ldd ? x : level, iq = ldd ? level : x;
      const auto L = cal.Inductance(id, iq);
      c.pts.push_back({x, ldd ? L.ldd_h : L.lqq_h});
      c.extrapolated.push_back(!cal.InMeasuredRegion(id, iq));
    }
    return c;
  };
  std::vector<Curve> dd, qq;
  for (double q : iq_levels) dd.push_back(sample(true, q));
  for (double d : id_levels) qq.push_back(sample(false, d));
  auto cover = [](const std::vector<Curve>& curves, double* lo, double* hi) {
    for (const auto& c : curves) {
      for (const auto& [x, y] : c.pts) {
        if (std::isfinite(y)) { *lo = std::min(*lo, y); *hi = std::max(*hi, y); }
      }
    }
    const double pad = 0.05 * std::max(*hi - *lo, 1e-6);
    *lo -= pad;
    *hi += pad;
  };
  cover(dd, &d_lo, &d_hi);
  cover(qq, &q_lo, &q_hi);
  const Panel pd{70, 40, 400, 320, id_lo, id_hi, d_lo, d_hi};
  const Panel pq{600, 40, 400, 320, 0.0, iq_hi, q_lo, q_hi};
  std::string s = absl::StrFormat(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"1090\" height=\"430\" font-family=\"sans-serif\" "
      "font-size=\"11\">\n<text x=\"70\" y=\"16\" font-size=\"13\">%s: fitted %s (lines; dashed = outside the "
      "measured region) against identified inductances (dots, +-1 sigma)</text>\n",
      cal.serial(), cal.family().Name());
  s += Frame(pd, "id [A]", "Ldd [mH]");
  s += Frame(pq, "iq [A]", "Lqq [mH]");
  auto polyline = [&](const Panel& p, const Curve& c, const char* colour) {
    // Split into runs of equal extrapolation state.
    std::string out;
    size_t k = 0;
    while (k < c.pts.size()) {
      const bool ex = c.extrapolated[k];
      std::string pts;
      size_t e = k;
      while (e < c.pts.size() && c.extrapolated[e] == ex) {
        pts += absl::StrFormat("%.1f,%.1f ", p.X(c.pts[e].first), p.Y(c.pts[e].second));
        ++e;
      }
      if (e < c.pts.size()) pts += absl::StrFormat("%.1f,%.1f ", p.X(c.pts[e].first), p.Y(c.pts[e].second));
      out += absl::StrFormat("<polyline points=\"%s\" fill=\"none\" stroke=\"%s\" stroke-width=\"1.5\"%s/>\n", pts,
                             colour, ex ? " stroke-dasharray=\"5 3\"" : "");
      k = e;
    }
    return out;
  };
  auto nearest = [](const std::vector<double>& levels, double v) {
    size_t best = 0;
    for (size_t k = 1; k < levels.size(); ++k)
      if (std::abs(levels[k] - v) < std::abs(levels[best] - v)) best = k;
    return best;
  };
  for (size_t k = 0; k < dd.size(); ++k) {
    s += polyline(pd, dd[k], kColours[k % 10]);
    s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" fill=\"%s\">iq %.0f A</text>\n", pd.x0 + pd.w + 5,
                         pd.y0 + 14 * (k + 1), kColours[k % 10], iq_levels[k] + 0.0);
  }
  for (size_t k = 0; k < qq.size(); ++k) {
    s += polyline(pq, qq[k], kColours[k % 10]);
    s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" fill=\"%s\">id %.0f A</text>\n", pq.x0 + pq.w + 5,
                         pq.y0 + 14 * (k + 1), kColours[k % 10], std::round(id_levels[k]) + 0.0);
  }
  auto dot = [&](const Panel& p, double x, double y, double sd, const char* colour) {
    return absl::StrFormat(
        "<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"%s\"/>"
        "<circle cx=\"%.1f\" cy=\"%.1f\" r=\"3\" fill=\"%s\"/>\n",
        p.X(x), p.Y(y - sd), p.X(x), p.Y(y + sd), colour, p.X(x), p.Y(y), colour);
  };
  for (const auto& o : obs) {
    s += dot(pd, o.id_a, o.ldd_h, o.ldd_h_std, kColours[nearest(iq_levels, std::abs(o.iq_a)) % 10]);
    s += dot(pq, std::abs(o.iq_a), o.lqq_h, o.lqq_h_std, kColours[nearest(id_levels, o.id_a) % 10]);
  }
  s += "</svg>\n";
  return s;
}

}  // namespace fluxcal::fit
