// spatial_harmonics on the diagnosis' side (effect_term.h): block kHarm,
// an inductance h cos(n theta_e) for each order n of kHarmOrders (one
// candidate per order; Model::harm_order selects it).
#include "absl/strings/str_format.h"
#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm SpatialHarmonicsTerm() {
  EffectTerm t;
  t.effect = "spatial_harmonics";
  for (int n : kHarmOrders) t.candidates.push_back({"spatial_harmonics", kHarm, n});
  t.describe = [](const Candidate& c, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    out->parameters["order"] = c.order;
    SetParam(out, "amplitude_h", m.Harm(p), kScaleHarm * Sd(f, kHarm, 0));
    out->explanation = absl::StrFormat("the identified inductance at standstill varies with rotor angle as "
                                       "cos(%d theta_e), beyond the saliency's 2 theta_e", c.order);
  };
  t.replay = [](const Model& m, const double* const* p, int harm_order, sim::ReplayOptions* opt) {
    opt->effects.order = p[kHarm][0] != 0.0 ? harm_order : 0;
    opt->effects.amplitude_h = m.Harm(p);
  };
  t.artefact_blocks = {kHarm};
  return t;
}

}  // namespace fluxcal::diag::detail
