// dc_link_sense_gain on the diagnosis' side (effect_term.h): block
// kUdcGain, Model::UdcGain scaling every applied voltage.
#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {

EffectTerm DcLinkSenseGainTerm() {
  EffectTerm t = OneBlockTerm("dc_link_sense_gain", kUdcGain);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    // udc_gain is the contract's name (docs/diagnosis-report.md);
    // udc_sense_gain, the catalogue's, stays beside it (same value).
    SetParam(out, "udc_gain", m.UdcGain(p), kScaleUdcGain * Sd(f, kUdcGain, 0));
    SetParam(out, "udc_sense_gain", m.UdcGain(p), kScaleUdcGain * Sd(f, kUdcGain, 0));
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    opt->effects.udc_sense_gain = m.UdcGain(p);
  };
  return t;
}

}  // namespace fluxcal::diag::detail
