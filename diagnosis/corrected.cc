#include "diagnosis/effects/effect_term.h"
#include "diagnosis/internal.h"

#include <algorithm>
#include <cmath>
#include <functional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "identification/inductance.h"

namespace fluxcal::diag::detail {

// The recording's fit data (fitting::FitDataFromRecording) freed of the
// measurement and drive effects the diagnosis found, for a refit through the
// fit's own families (docs/diagnosis.md, "The diagnosed calibration"). Each
// observation keeps its own noise; only the effects' share is removed:
//  - inductances: identified + (what identification would give from the
//    final model's phasors without the effects, at the true current) -
//    (the same with them);
//  - steady-state rows: at the true current (angle offset and sensor gains
//    undone), voltage minus the effects' share of the final model's
//    prediction;
//  - Rs and psi_pm: the final model's (motor properties, not artefacts).
fit::FitData CorrectedFitData(const io::RecordingSet& set, const Model& m, const Params& final_p,
                              const std::vector<ident::HfPointResult>& ids) {
  fit::FitData d = fit::FitDataFromRecording(set, ids);
  Model mc = m;
  mc.dead_nom_s = 0.0;   // no dead time acts in the clean model
  Params clean = final_p;
  // The test's drifts go too: the calibration holds the mean.
  for (const auto& term : EffectTerms()) {
    for (Block b : term.artefact_blocks) std::fill(clean.b[b].begin(), clean.b[b].end(), 0.0);
  }
  const auto pf = final_p.Ptrs(), pc = clean.Ptrs();
  d.rs_ohm = m.Rs(pf.data());
  d.psi_pm_prior_wb = m.psi_nom * (1 + kScalePsi * final_p.b[kPsi][0]);
  const Complex rot = std::polar(1.0, m.Offset(pf.data()));
  // Inductances: FitDataFromRecording keeps the identified points in order,
  // skipping the ones it rejects; match by operating point.
  for (auto& obs : d.inductances) {
    const HfObs* o = nullptr;
    for (const auto& h : m.hf) {
      if (std::abs(h.id_a - obs.id_a) < 1e-9 && std::abs(h.iq_a - obs.iq_a) < 1e-9) o = &h;
    }
    if (o == nullptr) continue;
    Complex i0e, i1e, i0c, i1c;
    m.PredictHf(pf.data(), *o, &i0e, &i1e);
    HfObs oc = *o;
    const Complex rot_o = std::polar(1.0, m.AngleError(pf.data(), o->locked, o->theta));
    const Complex it = rot_o * (o->locked ? m.TrueCurrent(pf.data(), Complex(o->id_a, o->iq_a), o->theta)
                                        : Complex(o->id_a, o->iq_a) / m.M1(pf.data()));
    oc.id_a = it.real();
    oc.iq_a = it.imag();
    oc.theta = o->theta - m.AngleError(pf.data(), o->locked, o->theta);
    mc.PredictHf(pc.data(), oc, &i0c, &i1c);
    auto le = ident::InductanceFromPhasors(i0e, i1e, o->v_eff, o->v_neg_eff, m.w_i, o->w_e);
    auto lc = ident::InductanceFromPhasors(i0c, i1c, o->v_eff, o->v_neg_eff, m.w_i, o->w_e);
    if (!le.ok() || !lc.ok()) continue;
    obs.id_a = oc.id_a;
    obs.iq_a = oc.iq_a;
    obs.ldd_h += lc->ldd_h - le->ldd_h;
    obs.lqq_h += lc->lqq_h - le->lqq_h;
    if (obs.ldq_h) *obs.ldq_h += lc->ldq_h - le->ldq_h;
  }
  for (size_t k = 0; k < d.steady_state.size() && k < m.ss.size(); ++k) {
    const SsObs& o = m.ss[k];
    SsObs oc = o;
    const Complex it = rot * Complex(o.id_a, o.iq_a) / m.M1(pf.data());
    oc.id_a = it.real();
    oc.iq_a = it.imag();
    const Complex u_corr = o.u - m.PredictSs(pf.data(), o) + mc.PredictSs(pc.data(), oc);
    const double zoh = sim::ZohGain(o.w_e, m.ts);   // o.u = zoh x the row's command
    auto& row = d.steady_state[k];
    row.id_a = it.real();
    row.iq_a = it.imag();
    row.ud_ref_v = u_corr.real() / zoh;
    row.uq_ref_v = u_corr.imag() / zoh;
    // The air-gap torque: the transducer's reading plus the mechanical loss.
    if (row.torque_nm) {
      *row.torque_nm += physics::MechanicalLossTorque(m.Friction(pf.data()), m.Viscous(pf.data()), o.speed_rpm);
    }
  }
  return d;
}

}  // namespace fluxcal::diag::detail
