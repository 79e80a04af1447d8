// Reference-frame and timing helpers shared by the twin and diagnosis, so
// that each convention is written once (docs/recording-format.md):
//  - amplitude-invariant Clarke: i_alpha = (2 ia - ib - ic) / 3,
//    i_beta = (ib - ic) / sqrt(3); its inverse for a balanced set;
//  - Park: x_dq = e^{-j theta} x_alphabeta (theta electrical);
//  - w_e = 2 pi p n / 60 (n in rpm, p pole pairs);
//  - the zero-order hold's gain on a vector rotating at w over one period T,
//    sin(x)/x with x = w T / 2 (the mean of e^{j w t} over the period).
#ifndef FLUXCAL_SIMULATION_FRAMES_H_
#define FLUXCAL_SIMULATION_FRAMES_H_

#include <cmath>
#include <complex>
#include <numbers>

namespace fluxcal::sim {

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kSqrt3 = 1.7320508075688772935;
// Temperature coefficient of copper resistance at 20-25 degC [1/K].
inline constexpr double kCopperAlphaPerK = 0.00393;

struct AlphaBeta {
  double alpha = 0, beta = 0;
};
struct Phases {
  double a = 0, b = 0, c = 0;
};

// Amplitude-invariant Clarke transform (the zero sequence drops out).
inline AlphaBeta Clarke(double a, double b, double c) {
  return {(2 * a - b - c) / 3.0, (b - c) / kSqrt3};
}
inline std::complex<double> ClarkeComplex(double a, double b, double c) {
  const AlphaBeta ab = Clarke(a, b, c);
  return {ab.alpha, ab.beta};
}
// Inverse Clarke without zero sequence.
inline Phases InverseClarke(double alpha, double beta) {
  return {alpha, -0.5 * alpha + 0.5 * kSqrt3 * beta, -0.5 * alpha - 0.5 * kSqrt3 * beta};
}
// Park (stationary -> rotor frame at electrical angle theta) and inverse.
inline void Park(double alpha, double beta, double theta, double* d, double* q) {
  const double c = std::cos(theta), s = std::sin(theta);
  *d = c * alpha + s * beta;
  *q = -s * alpha + c * beta;
}
inline void InversePark(double d, double q, double theta, double* alpha, double* beta) {
  const double c = std::cos(theta), s = std::sin(theta);
  *alpha = c * d - s * q;
  *beta = s * d + c * q;
}
// Electrical angular speed [rad/s] from mechanical speed [rpm].
inline double RpmToElectricalRadS(double speed_rpm, int pole_pairs) {
  return speed_rpm * pole_pairs * 2.0 * kPi / 60.0;
}
inline double ElectricalRadSToRpm(double w_e_rad_s, int pole_pairs) {
  return w_e_rad_s * 60.0 / (2.0 * kPi * pole_pairs);
}
// sin(x)/x, 1 at x = 0.
inline double Sinc(double x) { return std::abs(x) < 1e-12 ? 1.0 : std::sin(x) / x; }
// Gain of a zero-order hold of length period_s on a vector rotating at
// w_rad_s, relative to its value at the middle of the period.
inline double ZohGain(double w_rad_s, double period_s) { return Sinc(0.5 * w_rad_s * period_s); }
// Angle wrapped to [0, 2 pi).
inline double WrapAngle(double a) {
  a = std::fmod(a, 2 * kPi);
  return a < 0 ? a + 2 * kPi : a;
}

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_FRAMES_H_
