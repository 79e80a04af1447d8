// iron_loss on the diagnosis' side (effect_term.h): block kIronLoss, the
// conductance g = 1 / R_fe (Model::Gfe, linear in the model), reported as
// the resistance.
#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm IronLossTerm() {
  EffectTerm t = OneBlockTerm("iron_loss", kIronLoss);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    // Its deviation by the delta method.
    const double g = m.Gfe(p), sg = kScaleGfe * Sd(f, kIronLoss, 0);
    SetParam(out, "r_fe_ohm", g != 0.0 ? 1.0 / g : 0.0, g != 0.0 ? sg / (g * g) : 0.0);
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    opt->effects.r_fe_ohm = m.Gfe(p) > 0 ? 1.0 / m.Gfe(p) : 0.0;
  };
  return t;
}

}  // namespace fluxcal::diag::detail
