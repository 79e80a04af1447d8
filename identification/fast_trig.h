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
  // Quadrant fix-up without a switch: at speed the quadrant changes every
  // few samples and a mispredicted branch would cost more than the select.
  const long quadrant = static_cast<long>(q) & 3;
  const bool swap = (quadrant & 1) != 0;
  const double a = swap ? cr : sr, b = swap ? sr : cr;
  *s = (quadrant & 2) ? -a : a;
  *c = ((quadrant + 1) & 2) ? -b : b;
}

// e^{j theta_k} along a sampled angle: exact FastSinCos every 256 samples,
// and in between the previous value rotated by e^{j (theta_k - theta_k-1)}
// with a short Taylor series when the step is small (|d| < 0.2 rad: the
// degree-9/10 truncation is < 2e-15). Accumulated rounding over 256 steps
// stays below 1e-10. Falls back to FastSinCos for large steps (wraps).
class AngleRotor {
 public:
  void Next(double theta, double* s, double* c) {
    const double d = theta - last_;
    if ((count_++ & 255u) == 0 || !(std::abs(d) < 0.2)) {
      FastSinCos(theta, &s_, &c_);
    } else {
      // Branch-free small-angle rotation: encoder steps alternate between
      // neighbouring counts, so caching one step mispredicts; the degree-9/10
      // polynomial costs less than the mispredicted branch.
      const double d2 = d * d;
      const double sd = d * (1.0 + d2 * (-1.0 / 6 + d2 * (1.0 / 120 + d2 * (-1.0 / 5040 + d2 * (1.0 / 362880)))));
      const double cd = 1.0 + d2 * (-0.5 + d2 * (1.0 / 24 + d2 * (-1.0 / 720 + d2 * (1.0 / 40320 - d2 / 3628800.0))));
      const double ns = s_ * cd + c_ * sd;
      c_ = c_ * cd - s_ * sd;
      s_ = ns;
    }
    last_ = theta;
    *s = s_;
    *c = c_;
  }

 private:
  double last_ = 0.0, s_ = 0.0, c_ = 1.0;
  unsigned long count_ = 0;
};

}  // namespace fluxcal::ident

#endif  // FLUXCAL_IDENTIFICATION_FAST_TRIG_H_
