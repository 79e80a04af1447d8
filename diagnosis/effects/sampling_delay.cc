// sampling_delay on the diagnosis' side (effect_term.h): block kDelay,
// Model::Delay (the staircase delay of the HF phasors, w_e tau at speed).
#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm SamplingDelayTerm() {
  EffectTerm t = OneBlockTerm("sampling_delay", kDelay);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    SetParam(out, "delay_s", m.Delay(p), kScaleDelay * Sd(f, kDelay, 0));
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    opt->effects.delay_s = m.Delay(p);
  };
  return t;
}

}  // namespace fluxcal::diag::detail
