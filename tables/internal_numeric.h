// Small numeric helpers of the table solver and figures (internal to
// tables/, not installed).
#ifndef FLUXCAL_TABLES_INTERNAL_NUMERIC_H_
#define FLUXCAL_TABLES_INTERNAL_NUMERIC_H_

#include <algorithm>
#include <vector>

namespace fluxcal::tables::internal {

inline constexpr double kGolden = 0.61803398874989484820;

// Minimises f on [a, b]: coarse scan, then golden section around the best.
template <typename F>
double MinimiseScalar(F f, double a, double b, int scan = 16, int iters = 40) {
  double best = a, fbest = f(a);
  for (int k = 1; k <= scan; ++k) {
    const double x = a + (b - a) * k / scan;
    const double fx = f(x);
    if (fx < fbest) { fbest = fx; best = x; }
  }
  double lo = std::max(a, best - (b - a) / scan), hi = std::min(b, best + (b - a) / scan);
  double x1 = hi - kGolden * (hi - lo), x2 = lo + kGolden * (hi - lo);
  double f1 = f(x1), f2 = f(x2);
  for (int k = 0; k < iters; ++k) {
    if (f1 < f2) { hi = x2; x2 = x1; f2 = f1; x1 = hi - kGolden * (hi - lo); f1 = f(x1); }
    else { lo = x1; x1 = x2; f1 = f2; x2 = lo + kGolden * (hi - lo); f2 = f(x2); }
  }
  return 0.5 * (lo + hi);
}

// n points from a to b, both included (a alone for n = 1).
inline std::vector<double> Linspace(double a, double b, int n) {
  std::vector<double> v(n);
  for (int k = 0; k < n; ++k) v[k] = n == 1 ? a : a + (b - a) * k / (n - 1);
  return v;
}

}  // namespace fluxcal::tables::internal

#endif  // FLUXCAL_TABLES_INTERNAL_NUMERIC_H_
