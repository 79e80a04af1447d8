// hf_resistance on the diagnosis' side (effect_term.h): block kRhf,
// Model::RHf, in series with Rs in the HF phasors only.
#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm HfResistanceTerm() {
  EffectTerm t = OneBlockTerm("hf_resistance", kRhf);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    SetParam(out, "r_hf_ohm", m.RHf(p), kScaleRhf * Sd(f, kRhf, 0));
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    opt->effects.r_hf_ohm = m.RHf(p);
  };
  return t;
}

}  // namespace fluxcal::diag::detail
