#include "diagnosis/effects/effect_term.h"
#include "diagnosis/internal.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "simulation/twin.h"

namespace fluxcal::diag::detail {

// The fitted surfaces as a twin magnetic model (for waveform replay): one
// evaluator for the parameters (fitting/surface.h), and the last point's
// flux and inductance kept, since the plant's Newton steps ask for both at
// each point.
//
// Beyond the currents the set measured the surfaces are continued with the
// inductance at the box's edge (ContinuedSurface, internal.h).
MeasuredBox MeasuredBoxOf(const Model& m) {
  MeasuredBox box;
  auto widen = [&](double id, double iq) {
    box.id_lo_a = std::min(box.id_lo_a, id);
    box.id_hi_a = std::max(box.id_hi_a, id);
    box.iq_hi_a = std::max(box.iq_hi_a, std::abs(iq));
  };
  for (const auto& o : m.hf) widen(o.id_a, o.iq_a);
  for (const auto& o : m.dc) widen(o.id_a, o.iq_a);
  for (const auto& o : m.ss) widen(o.id_a, o.iq_a);
  return box;
}

void ContinuedSurface(const fit::SurfaceEvaluator& eval, const MeasuredBox& box, double id, double iq, double* pd,
                      double* pq, double* ldd, double* lqq, double* ldq) {
  const double id0 = std::clamp(id, box.id_lo_a, box.id_hi_a), iq0 = std::clamp(iq, -box.iq_hi_a, box.iq_hi_a);
  eval.Eval(id0, iq0, pd, pq, ldd, lqq, ldq);
  const double dd = id - id0, dq = iq - iq0;
  *pd += *ldd * dd + *ldq * dq;
  *pq += *ldq * dd + *lqq * dq;
}

class SurfaceModel : public sim::MagneticModel {
 public:
  SurfaceModel(const Model& m, const Params& p)
      : eval_(m.surf, p.b[kBase]), psi_pm_(m.PsiPm(p.Ptrs().data())), box_(MeasuredBoxOf(m)) {}
  sim::FluxLinkage Flux(double id, double iq, double) const override {
    Update(id, iq);
    return {last_.psi_d, last_.psi_q};
  }
  sim::DifferentialInductance Inductance(double id, double iq, double) const override {
    Update(id, iq);
    return {last_.ldd, last_.lqq, last_.ldq};
  }

 private:
  struct Point {
    double id = std::numeric_limits<double>::quiet_NaN(), iq = 0, psi_d = 0, psi_q = 0, ldd = 0, lqq = 0, ldq = 0;
  };
  void Update(double id, double iq) const {
    if (id == last_.id && iq == last_.iq) return;
    last_.id = id;
    last_.iq = iq;
    ContinuedSurface(eval_, box_, id, iq, &last_.psi_d, &last_.psi_q, &last_.ldd, &last_.lqq, &last_.ldq);
    last_.psi_d += psi_pm_;   // the family's psi_pm slot is 0 in the model's parameters
  }
  fit::SurfaceEvaluator eval_;
  double psi_pm_;
  MeasuredBox box_;
  mutable Point last_;
};

absl::StatusOr<std::vector<sim::ReplayPoint>> ReplayModel(const io::RecordingSet& set, const Model& m,
                                                          const Params& p, int harm_order) {
  SurfaceModel model(m, p);
  const auto ptr = p.Ptrs();
  sim::ReplayOptions opt;
  opt.substeps = 5;   // RK4 at 20 us: w_i h = 0.06, far inside its accuracy
  // Each effect's share at the model's parameters (diagnosis/effects/).
  for (const auto& term : EffectTerms()) {
    if (term.replay != nullptr) term.replay(m, ptr.data(), harm_order, &opt);
  }
  return sim::ReplayOpenLoop(set, model, opt);
}

bool ReplayRanAway(const io::Waveform& w, const sim::ReplayPoint& r) {
  double rec_peak = 0, sim_peak = 0;
  for (size_t s = 1; s < w.size() && s < r.ia_a.size(); ++s) {
    for (double v : {w.ia_a[s], w.ib_a[s], w.ic_a[s]}) rec_peak = std::max(rec_peak, std::abs(v));
    for (double v : {r.ia_a[s], r.ib_a[s], r.ic_a[s]}) {
      if (!std::isfinite(v)) return true;
      sim_peak = std::max(sim_peak, std::abs(v));
    }
  }
  return sim_peak > 10.0 * rec_peak + 1.0;
}

void LeaveOutUnheldPoints(const std::vector<ident::HfPointResult>& ids, std::vector<sim::ReplayPoint>* replay) {
  for (auto& r : *replay) {
    for (const auto& id : ids) {
      if (id.point != r.point || id.failure.empty()) continue;
      r.ia_a.clear();
      r.ib_a.clear();
      r.ic_a.clear();
    }
  }
}

double ReplaySpectrum(const io::RecordingSet& set, const std::vector<sim::ReplayPoint>& replay,
                      const std::vector<double>& freqs, std::vector<double>* spectrum) {
  spectrum->assign(freqs.size(), 0.0);
  double se = 0;
  size_t n_all = 0;
  const double fs = set.manifest.drive.f_sample_hz;
  for (size_t k = 0; k < replay.size(); ++k) {
    const auto& r = replay[k];
    const auto& w = set.waveforms[k];
    if (r.ia_a.size() != w.size() || ReplayRanAway(w, r)) continue;   // left out (LeaveOutUnheldPoints)
    se += r.residual_rms_a * r.residual_rms_a * 3.0 * (w.size() - 1);
    n_all += 3 * (w.size() - 1);
    std::vector<Complex> e(w.size());
    for (size_t s = 1; s < w.size(); ++s) {
      const double ea = r.ia_a[s] - w.ia_a[s], eb = r.ib_a[s] - w.ib_a[s], ec = r.ic_a[s] - w.ic_a[s];
      e[s] = sim::ClarkeComplex(ea, eb, ec);
    }
    for (size_t f = 0; f < freqs.size(); ++f) {
      // DFT bin by a rotating phasor (recurrence, renormalised).
      const Complex step = std::polar(1.0, -2 * kPi * freqs[f] / fs);
      Complex rot = step, acc = 0;
      for (size_t s = 1; s < w.size(); ++s) {
        acc += e[s] * rot;
        rot *= step;
      }
      (*spectrum)[f] += std::abs(acc) / static_cast<double>(w.size() - 1) / static_cast<double>(replay.size());
    }
  }
  return n_all ? std::sqrt(se / n_all) : 0.0;
}

}  // namespace fluxcal::diag::detail
