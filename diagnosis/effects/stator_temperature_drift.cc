// stator_temperature_drift on the diagnosis' side (effect_term.h): block
// kDrift, Rs rising with the recording order (Model::RsAt), reported as a
// drift: Rs at the first and the last point, and the rise.
#include <cmath>

#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm StatorTemperatureDriftTerm() {
  EffectTerm t = OneBlockTerm("stator_temperature_drift", kDrift);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    // A drift is reported as one (docs/diagnosis-report.md): Rs at the
    // first and the last point of the recording, and the rise.
    SetParam(out, "winding_temp_rise_k", kScaleDrift * p[kDrift][0], kScaleDrift * Sd(f, kDrift, 0));
    out->parameters["rs_start_ohm"] = m.RsAt(p, 0.0);
    out->parameters["rs_end_ohm"] = m.RsAt(p, 1.0);
    const double drs = m.Rs(p) * sim::kCopperAlphaPerK * kScaleDrift * Sd(f, kDrift, 0);
    out->parameter_std["rs_end_ohm"] = std::hypot(drs, kScaleRs * Sd(f, kRs, 0));
    out->parameter_std["rs_start_ohm"] = kScaleRs * Sd(f, kRs, 0);
  };
  return t;
}

}  // namespace fluxcal::diag::detail
