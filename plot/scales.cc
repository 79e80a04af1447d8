// What the axes and colour scales show: round ("nice") tick positions and
// their labels, decade labels, the continuous colour map and the palette of
// line colours.
#include <algorithm>
#include <cmath>
#include <cstdio>

#include "plot/internal.h"
#include "plot/plot.h"

namespace fluxcal::plot {

using internal::Fmt;

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

}  // namespace fluxcal::plot
