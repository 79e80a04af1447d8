// dead_time on the diagnosis' side (effect_term.h): block kDead, the dead
// time acting beyond the one the manifest declares uncompensated
// (Model::DeadTime), on the current-sign signatures of observations.cc.
#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm DeadTimeTerm() {
  EffectTerm t = OneBlockTerm("dead_time", kDead);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    // Effective dead time acting (declared uncompensated part included).
    SetParam(out, "dead_time_s", m.DeadTime(p), kScaleDead * Sd(f, kDead, 0));
    if (m.ith_estimated) {
      // An extension of docs/diagnosis-report.md's vocabulary: the soft
      // sign's current, profiled (diagnose.cc).
      out->parameters["i_th_a"] = m.ith_a;
      if (m.ith_std_a > 0) out->parameter_std["i_th_a"] = m.ith_std_a;
    }
    if (m.udc_ratio <= kTwoUdcRatio && m.udc_nom_v > 0) {
      // Per phase the error is (Td/Ts) Udc + V_th times the same soft
      // sign: at one Udc the finding's extra Td is a threshold of
      // (Td - Td_nominal) Udc / Ts just as well.
      out->alternatives.push_back(
          {"inverter_voltage_drop",
           {{"threshold_v", (m.DeadTime(p) - m.dead_nom_s) * m.udc_nom_v / m.ts}},
           "the held points share one DC-link voltage, and a switch threshold has the dead time's current-sign "
           "pattern there; points repeated at a second Udc (fluxcal simulate --second-udc-v) separate them: the "
           "dead time's error scales with Udc, the threshold does not"});
    }
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    opt->effects.dead_time_s = m.DeadTime(p);
    opt->effects.dead_time_i_th_a = m.ith_a;
  };
  return t;
}

}  // namespace fluxcal::diag::detail
