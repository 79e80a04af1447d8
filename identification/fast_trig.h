// Fast, accurate sine/cosine for the demodulators' inner loops.
//
// Why: std::sin/std::cos per sample cost ~20 ns and would cap the
// demodulators far below their throughput targets. Range reduction by
// multiples of pi/2 (Cody-Waite, two-term pi/2), then Taylor polynomials on
// |r| <= pi/4 to degree 16/17: truncation error < (pi/4)^17/17! ~ 4e-17, so
// the result matches std::sin/cos to a few ulp for |x| < 1e6 rad.
#ifndef FLUXCAL_IDENTIFICATION_FAST_TRIG_H_
#define FLUXCAL_IDENTIFICATION_FAST_TRIG_H_

#include <cmath>

namespace fluxcal::ident {

inline void FastSinCos(double x, double* s, double* c) {
  constexpr double kTwoOverPi = 0.63661977236758134308;
  constexpr double kPiOver2Hi = 1.57079632679489655800e+00;
  constexpr double kPiOver2Lo = 6.12323399573676603587e-17;
  const double q = std::nearbyint(x * kTwoOverPi);
  const double r = (x - q * kPiOver2Hi) - q * kPiOver2Lo;
  const double r2 = r * r;
  // sin r = r (1 - r^2/3! + r^4/5! - ...), cos r = 1 - r^2/2! + ...
  const double sr =
      r * (1.0 + r2 * (-1.0 / 6 + r2 * (1.0 / 120 + r2 * (-1.0 / 5040 + r2 * (1.0 / 362880 +
          r2 * (-1.0 / 39916800 + r2 * (1.0 / 6227020800.0 + r2 * (-1.0 / 1307674368000.0 +
          r2 * (1.0 / 355687428096000.0)))))))));
  const double cr =
      1.0 + r2 * (-0.5 + r2 * (1.0 / 24 + r2 * (-1.0 / 720 + r2 * (1.0 / 40320 +
          r2 * (-1.0 / 3628800 + r2 * (1.0 / 479001600.0 + r2 * (-1.0 / 87178291200.0 +
          r2 * (1.0 / 20922789888000.0))))))));
  const long quadrant = static_cast<long>(q) & 3;
  switch (quadrant) {
    case 0: *s = sr; *c = cr; break;
    case 1: *s = cr; *c = -sr; break;
    case 2: *s = -sr; *c = -cr; break;
    default: *s = -cr; *c = sr; break;
  }
}

}  // namespace fluxcal::ident

#endif  // FLUXCAL_IDENTIFICATION_FAST_TRIG_H_
