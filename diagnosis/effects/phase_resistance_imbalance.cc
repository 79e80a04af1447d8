// phase_resistance_imbalance on the diagnosis' side (effect_term.h): block
// kRImb, r2 = (1/3) sum dr_x e^{j 2 phi_x} (Model::RImb; the common part
// is stator_resistance), reported per phase as the zero-sum set and as
// each phase's resistance.
#include <algorithm>
#include <cmath>

#include "diagnosis/effects/effect_term.h"

namespace fluxcal::diag::detail {
namespace {

// dr_x = 2 Re(r2 e^{-j 2 phi_x}).
double PhaseDr(Complex r2, int x) { return 2 * std::real(r2 * std::polar(1.0, -2 * kPhasePhi[x])); }

}  // namespace

EffectTerm PhaseResistanceImbalanceTerm() {
  EffectTerm t = OneBlockTerm("phase_resistance_imbalance", kRImb);
  t.describe = [](const Candidate&, const Model& m, const FitOut& f, const double* const* p,
                  Finding* out) {
    const char* names[3] = {"dr_a_ohm", "dr_b_ohm", "dr_c_ohm"};
    // The contract's r_x_ohm: each phase's resistance, the model's Rs
    // (the common part) plus its zero-sum share.
    const char* absolute[3] = {"r_a_ohm", "r_b_ohm", "r_c_ohm"};
    const double sdr = kScaleRImb * std::max(Sd(f, kRImb, 0), Sd(f, kRImb, 1));
    for (int x = 0; x < 3; ++x) {
      const double dr = PhaseDr(m.RImb(p), x);
      out->parameters[names[x]] = dr;
      out->parameter_std[names[x]] = 2 * sdr;
      out->parameters[absolute[x]] = m.Rs(p) + dr;
      out->parameter_std[absolute[x]] = std::hypot(2 * sdr, kScaleRs * Sd(f, kRs, 0));
    }
  };
  t.replay = [](const Model& m, const double* const* p, int, sim::ReplayOptions* opt) {
    double* dr[3] = {&opt->effects.dr_a_ohm, &opt->effects.dr_b_ohm, &opt->effects.dr_c_ohm};
    for (int x = 0; x < 3; ++x) *dr[x] = PhaseDr(m.RImb(p), x);
  };
  return t;
}

}  // namespace fluxcal::diag::detail
