// position_offset on the diagnosis' side (effect_term.h): block kOffset,
// Model::Offset (Model::AngleError composes it with the sensor's harmonic).
#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm PositionOffsetTerm() {
  EffectTerm t = OneBlockTerm("position_offset", kOffset);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    SetParam(out, "offset_rad", m.Offset(p), kScaleOffset * Sd(f, kOffset, 0));
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    opt->effects.offset_rad = m.Offset(p);
  };
  return t;
}

}  // namespace fluxcal::diag::detail
