// current_sensor_offset on the diagnosis' side (effect_term.h): block
// kSensorOffset, the offset in alpha-beta (Model::SensorOffset; the zero
// sequence of three offsets is unobservable), reported as a zero-sum set
// of phase offsets (PhaseOffset, verdict.cc).
#include <algorithm>

#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm CurrentSensorOffsetTerm() {
  EffectTerm t = OneBlockTerm("current_sensor_offset", kSensorOffset);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    const char* names[3] = {"offset_a_a", "offset_b_a", "offset_c_a"};
    const double sdo = kScaleSensorOffset * std::max(Sd(f, kSensorOffset, 0), Sd(f, kSensorOffset, 1));
    for (int x = 0; x < 3; ++x) {
      out->parameters[names[x]] = PhaseOffset(m.SensorOffset(p), x);
      out->parameter_std[names[x]] = sdo;
    }
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    const Complex so = m.SensorOffset(p);
    opt->effects.offset_a_a = PhaseOffset(so, 0);
    opt->effects.offset_b_a = PhaseOffset(so, 1);
    opt->effects.offset_c_a = PhaseOffset(so, 2);
  };
  return t;
}

}  // namespace fluxcal::diag::detail
