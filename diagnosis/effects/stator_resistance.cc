// stator_resistance on the diagnosis' side (effect_term.h): block kRs,
// Model::Rs. A motor property: the diagnosed calibration keeps it.
#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm StatorResistanceTerm() {
  EffectTerm t = OneBlockTerm("stator_resistance", kRs, /*artefact=*/false);   // a motor property
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    SetParam(out, "rs_ohm", m.Rs(p), kScaleRs * Sd(f, kRs, 0));
    if (m.Rs(p) > m.rs_nom) {
      // v_x = (Rs + r_on) i_x + ... in the DC, HF and steady-state
      // responses alike: one device of each leg always carries the phase
      // current.
      out->alternatives.push_back(
          {"inverter_voltage_drop",
           {{"slope_ohm", m.Rs(p) - m.rs_nom}},
           "the switches' on-state slope r_on is in series with the winding in every response seen through the "
           "inverter's commands; a four-wire resistance measured at the motor terminals separates them"});
    }
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) { opt->rs_ohm = m.Rs(p); };
  return t;
}

}  // namespace fluxcal::diag::detail
