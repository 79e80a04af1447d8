// position_sensor_harmonic on the diagnosis' side (effect_term.h): block
// kAngleHarm, c = amplitude e^{j phase} (Model::AngleHarm), linear in the
// block; reported as amplitude and phase.
#include <algorithm>
#include <cmath>

#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm PositionSensorHarmonicTerm() {
  EffectTerm t = OneBlockTerm("position_sensor_harmonic", kAngleHarm);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    const Complex c = m.AngleHarm(p);
    const double sa = kScaleAngleHarm * std::max(Sd(f, kAngleHarm, 0), Sd(f, kAngleHarm, 1));
    SetParam(out, "harmonic_amplitude_rad", std::abs(c), sa);
    SetParam(out, "harmonic_phase_rad", std::arg(c), std::abs(c) > 0 ? sa / std::abs(c) : kPi);
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    opt->effects.harmonic_amplitude_rad = std::abs(m.AngleHarm(p));
    opt->effects.harmonic_phase_rad = std::arg(m.AngleHarm(p));
  };
  return t;
}

}  // namespace fluxcal::diag::detail
