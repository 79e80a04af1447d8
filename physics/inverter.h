// Inverter non-idealities, per phase x in {a, b, c}:
//  - dead time Td and switch threshold V_th: the applied voltage falls short
//    of the command by ((Td / Ts) Udc + V_th) sign(i_x) (the classic
//    average-value dead-time model, e.g. Choi & Sul, IEEE TPE 1996); the sign
//    is smoothed to tanh(i_x / i_th) because the output capacitances make the
//    commutation current-dependent near zero current (the soft sign);
//  - MeanSoftSign: the mean of tanh(i / i_th) over a PWM period in which the
//    current moves linearly from i0 to i1,
//    (i_th / (i1 - i0)) [ln cosh(i1 / i_th) - ln cosh(i0 / i_th)].
#ifndef FLUXCAL_PHYSICS_INVERTER_H_
#define FLUXCAL_PHYSICS_INVERTER_H_

#include <cmath>

#include "physics/frames.h"

namespace fluxcal::physics {

// The soft sign tanh(i / i_th) of a phase current.
template <typename T>
T SoftSign(const T& i_a, double i_th_a) {
  using std::tanh;
  return tanh(i_a / i_th_a);
}
// The per-phase dead-time + threshold voltage error [V]:
// -((Td / Ts) Udc + V_th) tanh(i / i_th).
template <typename T>
T DeadTimePhaseError(const T& i_a, double dead_time_s, double ts_s, double udc_v, double threshold_v,
                     double i_th_a) {
  return -((dead_time_s / ts_s) * udc_v + threshold_v) * SoftSign(i_a, i_th_a);
}
// The alpha-beta vector (amplitude-invariant Clarke) of the per-phase
// voltages gain tanh(i_x / i_th): with gain -((Td / Ts) Udc + V_th) the
// inverter's error vector; with gain Udc / Ts its signature per second of
// dead time.
template <typename T>
AlphaBeta<T> SoftSignVector(const T& ia, const T& ib, const T& ic, double gain, double i_th_a) {
  const T ea = gain * SoftSign(ia, i_th_a), eb = gain * SoftSign(ib, i_th_a), ec = gain * SoftSign(ic, i_th_a);
  return Clarke(ea, eb, ec);
}
// Mean of the soft sign over a linear current ramp i0 -> i1 (see above);
// ln cosh written as |x| + log1p(e^{-2|x|}) - ln 2 to stay finite.
inline double MeanSoftSign(double i0, double i1, double ith_a) {
  const double d = i1 - i0;
  auto lc = [](double x) { const double a = std::abs(x); return a + std::log1p(std::exp(-2 * a)) - std::log(2.0); };
  if (std::abs(d) < 1e-6 * ith_a) return std::tanh(0.5 * (i0 + i1) / ith_a);
  return ith_a / d * (lc(i1 / ith_a) - lc(i0 / ith_a));
}

}  // namespace fluxcal::physics

#endif  // FLUXCAL_PHYSICS_INVERTER_H_
