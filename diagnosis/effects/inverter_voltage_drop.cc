// inverter_voltage_drop on the diagnosis' side (effect_term.h): block kVth,
// the switches' threshold (Model::Vth) on the dead time's soft-sign
// signature per volt; its slope r_on lives in Rs (stator_resistance names
// it as the alternative). Testable only where the held points span two
// DC-link voltages: at one it is the dead time's signature exactly, and
// the dead_time finding names it as the alternative.
#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm InverterVoltageDropTerm() {
  EffectTerm t = OneBlockTerm("inverter_voltage_drop", kVth);
  t.testable = [](const Candidate&, const Model& m) { return m.udc_ratio > kTwoUdcRatio; };
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    SetParam(out, "threshold_v", m.Vth(p), kScaleVth * Sd(f, kVth, 0));
    if (m.ith_estimated) {   // the same soft sign as the dead time's
      out->parameters["i_th_a"] = m.ith_a;
      if (m.ith_std_a > 0) out->parameter_std["i_th_a"] = m.ith_std_a;
    }
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    opt->effects.threshold_v = m.Vth(p);
  };
  return t;
}

}  // namespace fluxcal::diag::detail
