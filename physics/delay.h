// The digital controller's timing (identification/demod.h eq. (V1),
// docs/identification.md): a command computed from samples at t_k is applied
// one PWM period T later and held (zero-order hold) for one period. On a
// vector rotating at w this is
//  - the hold's gain relative to the middle of the period: the mean of
//    e^{j w t} over the period, sin(x) / x with x = w T / 2;
//  - the delay of the held command's centre: 1.5 T (one period of compute
//    and the half period of the hold), so delay-compensated controllers
//    advance the Park angle by 1.5 w T;
//  - an extra delay tau = (n + a) T of the held (staircase) command seen in
//    the *sampled* current of an inductive load (R T / L << 1): the current is
//    piecewise linear with corners at the steps, each sample falls a fraction
//    1 - a into a segment, so i(t_k) = (1 - a) i0(t_{k-n}) + a i0(t_{k-n-1}),
//    i.e. the phasor factor e^{-j w n T} ((1 - a) + a e^{-j w T}) -- not the
//    pure e^{-j w tau}: at half a sample its magnitude is cos(w T / 2).
#ifndef FLUXCAL_PHYSICS_DELAY_H_
#define FLUXCAL_PHYSICS_DELAY_H_

#include <cmath>
#include <complex>

namespace fluxcal::physics {

// sin(x) / x, 1 at x = 0.
template <typename T>
T Sinc(const T& x) {
  using std::abs;
  using std::sin;
  return abs(x) < 1e-12 ? T(1.0) : T(sin(x) / x);
}
// Gain of a zero-order hold of length period_s on a vector rotating at w_rad_s.
template <typename T>
T ZohGain(const T& w_rad_s, double period_s) {
  return Sinc(T(0.5 * w_rad_s * period_s));
}
// The angle [rad] by which the applied voltage lags the command computed
// at a sample: 1.5 w T (one period of compute delay plus half a period of hold).
template <typename T>
T ControlDelayAngle(const T& w_rad_s, double period_s) {
  return 1.5 * w_rad_s * period_s;
}

// The staircase delay factor above, for a sampling period ts_s.
inline std::complex<double> StaircaseDelay(double w_rad_s, double tau_s, double ts_s) {
  const double q = tau_s / ts_s, n = std::floor(q), a = q - n;
  return std::polar(1.0, -w_rad_s * n * ts_s) * ((1.0 - a) + a * std::polar(1.0, -w_rad_s * ts_s));
}

}  // namespace fluxcal::physics

#endif  // FLUXCAL_PHYSICS_DELAY_H_
