// Spline families the fitting tests build by hand (tests/fitting only).
#ifndef FLUXCAL_TESTS_FITTING_SPLINE_FAMILIES_H_
#define FLUXCAL_TESTS_FITTING_SPLINE_FAMILIES_H_

#include <cstdint>
#include <random>
#include <vector>

#include "fitting/flux_family.h"

namespace fluxcal::fit {

// A symmetric smoothing spline with `spans` on id in [id_lo_a, id_hi_a] and
// `spans_q` on iq in [iq_lo_a, iq_hi_a]; `mirrored`: the mirrored layout,
// else the folded one an older calibration was written with.
inline Family SymmetricSmoothSpline(int spans, double id_lo_a, double id_hi_a, int spans_q, double iq_lo_a,
                                    double iq_hi_a, bool mirrored) {
  Family f;
  f.kind = Family::kSpline;
  f.spline.spans = spans;
  f.spline.id_lo_a = id_lo_a;
  f.spline.id_hi_a = id_hi_a;
  f.spline.smoothing = true;
  f.spline.symmetric = true;
  f.spline.mirrored = mirrored;
  f.spline.spans_q = spans_q;
  f.spline.iq_lo_a = iq_lo_a;
  f.spline.iq_hi_a = iq_hi_a;
  return f;
}

// Coefficients of f drawn from N(0, 1) with `seed`, psi_pm 0.0114 Wb as
// parameter 0: whatever a fit could find.
inline std::vector<double> RandomCoefficients(const Family& f, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> nd(0, 1);
  std::vector<double> p(f.NumParams());
  p[0] = 0.0114;
  for (size_t k = 1; k < p.size(); ++k) p[k] = nd(rng);
  return p;
}

}  // namespace fluxcal::fit

#endif  // FLUXCAL_TESTS_FITTING_SPLINE_FAMILIES_H_
