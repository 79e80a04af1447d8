// Electromagnetic torque of a three-phase synchronous machine in the rotor
// frame (docs/recording-format.md, peak-valued amplitude-invariant dq):
//   T = 1.5 p (psi_d iq - psi_q id).
// Derivation: the co-energy W'(id, iq, theta_m) gives T = dW'/dtheta_m at
// constant current; with the power balance p_in = 1.5 (ud id + uq iq) (the
// factor 3/2 undoes the amplitude-invariant scaling of the phase power) the
// motional emf terms w_e (psi_d iq - psi_q id) are the converted power, and
// w_e = p w_m gives the torque above. It holds for any (saturated,
// cross-coupled) flux map psi(id, iq) without spatial harmonics.
#ifndef FLUXCAL_PHYSICS_TORQUE_H_
#define FLUXCAL_PHYSICS_TORQUE_H_

#include "physics/speed.h"

namespace fluxcal::physics {

// Torque [N m] from the flux linkages [Wb] and currents [A]. The flux and the
// current may be of different scalar types (a ceres::Jet flux with measured
// double currents); the result is their common type. Evaluated as
// (1.5 p) (psi_d iq - psi_q id) so that every caller rounds the same way.
template <typename F, typename I>
auto ElectromagneticTorque(int pole_pairs, const F& psi_d, const F& psi_q, const I& id, const I& iq) {
  return 1.5 * pole_pairs * (psi_d * iq - psi_q * id);
}
// d T / d i along the current, for a Newton step on the torque: with the
// differential inductances Ldq = d psi_d / d iq, Lqq = d psi_q / d iq,
// dT/diq = 1.5 p (psi_d + Ldq iq - Lqq id).
template <typename T>
T TorqueSlopeIq(int pole_pairs, const T& psi_d, const T& ldq, const T& lqq, const T& id, const T& iq) {
  return 1.5 * pole_pairs * (psi_d + ldq * iq - lqq * id);
}

// What a shaft torque transducer reads below the air-gap torque: the
// mechanical loss between them, bearing and seal friction T_f opposing the
// rotation (Coulomb) and drag b w_m growing with the speed (windage,
// lubricant), T_loss = T_f sign(n) + b w_m = sign(n) (T_f + b |w_m|), so
// T_shaft = T_em - T_loss (a motoring machine delivers less, a braking one
// brakes more). With one direction of rotation T_f is indistinguishable
// from the transducer's zero offset (docs/diagnosis.md, "Torque loss").
// Templated so that a Jet parameter differentiates through it.
template <typename T>
T MechanicalLossTorque(const T& friction_nm, const T& viscous_nm_per_rad_s, double speed_rpm) {
  const double w_m = RpmToMechanicalRadS(speed_rpm);
  const double s = speed_rpm > 0 ? 1.0 : (speed_rpm < 0 ? -1.0 : 0.0);
  return s * (friction_nm + viscous_nm_per_rad_s * (s * w_m));
}

}  // namespace fluxcal::physics

#endif  // FLUXCAL_PHYSICS_TORQUE_H_
