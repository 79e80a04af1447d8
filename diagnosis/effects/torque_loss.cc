// torque_loss on the diagnosis' side (effect_term.h): block kTorqueLoss,
// (loss at the torque rows' mean speed, drag) so that its two parameters
// are not collinear (Model::Friction, Model::Viscous), on the
// steady-state rows' torque only.
#include <algorithm>
#include <cmath>

#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm TorqueLossTerm() {
  EffectTerm t = OneBlockTerm("torque_loss", kTorqueLoss);
  // Its two parameters, and one more row to see them.
  t.testable = [](const Candidate&, const Model& m) {
    return std::count_if(m.ss.begin(), m.ss.end(), [](const SsObs& o) { return o.has_torque; }) >= 3;
  };
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    // Reported as friction and drag (physics/torque.h); the block's first
    // parameter is the loss at the rows' mean speed, so the friction's
    // deviation is that of T_ref - b w_ref (covariance neglected: the
    // centring makes the two nearly independent).
    const double sb = kScaleViscous * Sd(f, kTorqueLoss, 1);
    const double s_ref = kScaleFriction * Sd(f, kTorqueLoss, 0);
    SetParam(out, "friction_nm", m.Friction(p), std::hypot(s_ref, sb * m.torque_ref_rad_s));
    SetParam(out, "viscous_nm_per_rad_s", m.Viscous(p), sb);
  };
  return t;
}

}  // namespace fluxcal::diag::detail
