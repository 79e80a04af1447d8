// Twin motors that bend like measured machines, not like the twin's own
// analytic family (simulation/saturation_model.h): closed-form co-energies
// with the traits real flux maps show (docs/fitting.md, "Real machines"):
//   - an inductance that falls through a knee and then levels off (q-axis
//     bridge or rib saturation), in both axes;
//   - cross saturation whose Ldd falls with |iq| and whose Ldq changes with
//     both currents;
//   - psi_q(id, 0) != 0 away from id = 0 (an asymmetric rotor);
//   - a small region of negative Ldd near zero current.
// Each is the gradient of one co-energy W(id, iq), so the map is reciprocal
// (Ldq = Ldqd) and the twin can simulate any recording of it.
#ifndef FLUXCAL_SIMULATION_TRAIT_MOTOR_H_
#define FLUXCAL_SIMULATION_TRAIT_MOTOR_H_

#include <string>
#include <vector>

#include "simulation/magnetic_model.h"

namespace fluxcal::sim {

// W(id, iq) = psi_pm id + S(id; ld0, lds, id_knee) + S(iq; lq0, lqs, iq_knee)
//           - cross G(id) H(iq) + psi_q_offset sin(id / id_knee) iq
//           + bump exp(-(id^2 + iq^2) / bump_r^2),
// with the saturating primitive
//   S(x; L0, Ls, I) = Ls x^2 / 2 + (L0 - Ls) I^2 ln cosh(x / I),
//   S'' = Ls + (L0 - Ls) sech^2(x / I)   (falls from L0 to Ls, levels off),
// G(id) = S(id; 1, 0.2, id_knee) / id_knee and H(iq) = S(iq; 1, 0.3,
// iq_knee) / iq_knee, both in A, so `cross_h` is in H (its contribution to
// Ldd, -cross G'' H, grows with |iq|: Ldd falls with iq; Ldq = -cross G' H').
// Ldd(0, 0) = ld0 - 2 bump / bump_r^2.
struct MotorTraits {
  std::string name;
  double psi_pm_wb = 0;
  double ld0_h = 0, lds_h = 0, id_knee_a = 1;
  double lq0_h = 0, lqs_h = 0, iq_knee_a = 1;
  double cross_h = 0;
  double psi_q_offset_wb = 0;
  double bump_wb_a = 0, bump_r_a = 1;
};

class TraitMotor : public MagneticModel {
 public:
  explicit TraitMotor(MotorTraits t) : t_(std::move(t)) {}
  FluxLinkage Flux(double id_a, double iq_a, double temperature_c = 25.0) const override;
  // Central differences of Flux (h = 1e-4 of the knee currents): the
  // truncation error, ~h^2 psi''', is below 1e-8 of the inductance.
  DifferentialInductance Inductance(double id_a, double iq_a, double temperature_c = 25.0) const override;
  const MotorTraits& traits() const { return t_; }

 private:
  MotorTraits t_;
};

// The four trait motors, scaled to currents up to `i_max_a` (id in
// [-i_max_a, 0], iq in [0, i_max_a]): "pm-syrm" (psi_pm ~10 % of the q
// flux, Lq 5x Ld, rib saturation, cross saturation), "ipm-bridge" (Lqq falls
// 10x through a knee at 15 % of the range and levels off), "psi-q-offset"
// (psi_q(id, 0) up to ~5 % of scale), "negative-slope" (Ldd < 0 near zero
// current). `flux_scale` multiplies every flux (and inductance), e.g. to
// keep a recording plan's speeds inside the inverter's voltage.
std::vector<MotorTraits> RealLikeMotors(double i_max_a, double flux_scale = 1.0);

// Machines of kinds the fit was not developed on, as a check that it holds
// beyond the four above (tests/fitting/real_maps_test.cc, OtherKinds),
// scaled the same way: "syrm" (synchronous reluctance, no magnet: psi_pm = 0,
// Lq0 10x Ld0, Lqq falling 10x through a knee at 15 % of the range),
// "spm" (surface magnets: Ld ~ Lq, mild saturation), "strong-cross" (|Ldq|
// up to 0.2 mH against Ldd 0.13-0.3 mH: det L near zero at the region's
// corner), "deep-sat" (Ldd falling 6x and Lqq 9x through knees at 17-20 %
// of the range).
std::vector<MotorTraits> OtherKindMotors(double i_max_a, double flux_scale = 1.0);

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_TRAIT_MOTOR_H_
