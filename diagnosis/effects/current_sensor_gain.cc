// current_sensor_gain on the diagnosis' side (effect_term.h): block kGain,
// measured = m1 i + m2 conj(i) in alpha-beta (Model::M1, Model::M2),
// reported as the three phase gains (PhaseGain, verdict.cc).
#include <algorithm>
#include <cmath>

#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm CurrentSensorGainTerm() {
  EffectTerm t = OneBlockTerm("current_sensor_gain", kGain);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    const char* names[3] = {"gain_a", "gain_b", "gain_c"};
    const double sdr = kScaleGain * std::max(Sd(f, kGain, 0), Sd(f, kGain, 1));
    for (int x = 0; x < 3; ++x) {
      out->parameters[names[x]] = PhaseGain(m.M1(p), m.M2(p), x);
      out->parameter_std[names[x]] = std::hypot(2 * sdr, kScaleGain * Sd(f, kGain, 2));
    }
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    double* g[3] = {&opt->effects.gain_a, &opt->effects.gain_b, &opt->effects.gain_c};
    for (int x = 0; x < 3; ++x) *g[x] = PhaseGain(m.M1(p), m.M2(p), x);
  };
  return t;
}

}  // namespace fluxcal::diag::detail
