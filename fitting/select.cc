// Select, the fit's choice among its candidate families (internal to
// fitting/): the region the data measured, the candidates the model name
// and the data allow, each solved, the physical one with the lowest
// cross-validation score kept and reported.
#include "fitting/select.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "fitting/flux_error.h"
#include "fitting/large_signal.h"
#include "fitting/parallel.h"
#include "fitting/solve.h"
#include "fitting/surface.h"
#include "io/flux_map.h"

namespace fluxcal::fit::internal {
namespace {

// Spans of the symmetric smoothing spline's iq knots over the measured |iq|
// range (SmoothFamily): docs/fitting.md has what 6, 8, 9, 11, 12 and 16 did
// instead.
constexpr int kSmoothSpansIqHalf = 10;

// Which halves of the iq axis the data measured. The machine's symmetry
// (psi_d even, psi_q odd in iq: a rotor symmetric about its d axis) is the
// default hypothesis; only observations on both sides of iq = 0 can show
// that a map departs from it, and only they pin an asymmetric model's
// other half (fitted to one half, smooth-asym continued its psi_q(id, 0)
// slope into iq < 0 and was 62 % off the public map there, Ldd -9.5 mH at
// (-10, -12) A). A half counts as measured when
//  - it holds at least kHalfMinShare of all observations (HF points,
//    steady-state rows and flux nodes, one each) and at least three: a stray
//    row or two cannot set half the map, and
//  - its observations span at least kHalfMinSpan of the largest |iq|
//    (0 included when points lie on iq = 0): one iq level does not show how
//    the half bends;
// observations within kZeroBand of the largest |iq| of iq = 0 (a set point
// of 0 A read back as a few mA either way, "-0.0") belong to both halves.
// If neither half passes, the one with more observations is taken (both
// empty: the positive). The signed extent of a half not measured ends at 0.
constexpr double kZeroBand = 0.05, kHalfMinShare = 0.10, kHalfMinSpan = 0.25;
struct MeasuredIq {
  IqHalves halves = IqHalves::kPositive;
  double lo_a = 0, hi_a = 0;   // signed extent of the measured halves
  int n_pos = 0, n_neg = 0, n = 0;
};
MeasuredIq MeasuredIqOf(const FitData& d) {
  std::vector<double> iq;
  for (const auto& o : d.inductances) iq.push_back(o.iq_a);
  for (const auto& o : d.steady_state) iq.push_back(o.iq_a);
  for (const auto& o : d.fluxes) iq.push_back(o.iq_a);
  MeasuredIq m;
  m.n = static_cast<int>(iq.size());
  if (iq.empty()) return m;
  double q_max = 0, lo = iq[0], hi = iq[0];
  for (double q : iq) {
    q_max = std::max(q_max, std::abs(q));
    lo = std::min(lo, q);
    hi = std::max(hi, q);
  }
  const double band = kZeroBand * q_max;
  bool on_zero = false;
  double pos_lo = 1e300, pos_hi = 0, neg_lo = 1e300, neg_hi = 0;   // |iq| extent per side
  for (double q : iq) {
    if (std::abs(q) <= band) {
      on_zero = true;
    } else if (q > 0) {
      ++m.n_pos;
      pos_lo = std::min(pos_lo, q);
      pos_hi = std::max(pos_hi, q);
    } else {
      ++m.n_neg;
      neg_lo = std::min(neg_lo, -q);
      neg_hi = std::max(neg_hi, -q);
    }
  }
  const int need = std::max(3, static_cast<int>(std::ceil(kHalfMinShare * m.n)));
  auto measured = [&](int count, double a, double b) {
    if (count < need) return false;
    const double from = on_zero ? 0.0 : a;
    return b - from >= kHalfMinSpan * q_max;
  };
  bool pos = measured(m.n_pos, pos_lo, pos_hi), neg = measured(m.n_neg, neg_lo, neg_hi);
  if (!pos && !neg) (m.n_neg > m.n_pos ? neg : pos) = true;
  m.halves = pos && neg ? IqHalves::kBoth : (pos ? IqHalves::kPositive : IqHalves::kNegative);
  m.lo_a = neg ? lo : std::max(lo, 0.0);
  m.hi_a = pos ? hi : std::min(hi, 0.0);
  if (m.lo_a > m.hi_a) m.lo_a = m.hi_a = 0.0;   // e.g. the only points of the measured half near 0
  return m;
}

// The region the screened data measured: id and |iq| extents over every
// observation, the signed iq extent, and the halves of the iq axis.
struct DataRegion {
  double id_min = 0, id_max = 0, iq_min = 0, iq_max = 0;   // iq: |iq|
  double iq_signed_min = 0, iq_signed_max = 0;
  MeasuredIq measured_iq;
};
DataRegion RegionOf(const FitData& d) {
  double id_min = std::numeric_limits<double>::max(), id_max = -id_min, iq_min = id_min, iq_max = -id_min;
  double iq_signed_min = id_min, iq_signed_max = -id_min;
  auto note_iq = [&](double iq) {
    iq_signed_min = std::min(iq_signed_min, iq);
    iq_signed_max = std::max(iq_signed_max, iq);
  };
  for (const auto& obs : d.inductances) note_iq(obs.iq_a);
  for (const auto& obs : d.steady_state) note_iq(obs.iq_a);
  for (const auto& obs : d.fluxes) note_iq(obs.iq_a);
  for (const auto& obs : d.inductances) {
    id_min = std::min(id_min, obs.id_a); id_max = std::max(id_max, obs.id_a);
    iq_min = std::min(iq_min, std::abs(obs.iq_a)); iq_max = std::max(iq_max, std::abs(obs.iq_a));
  }
  for (const auto& s : d.steady_state) {
    id_min = std::min(id_min, s.id_a); id_max = std::max(id_max, s.id_a);
    iq_min = std::min(iq_min, std::abs(s.iq_a)); iq_max = std::max(iq_max, std::abs(s.iq_a));
  }
  for (const auto& s : d.fluxes) {
    id_min = std::min(id_min, s.id_a); id_max = std::max(id_max, s.id_a);
    iq_min = std::min(iq_min, std::abs(s.iq_a)); iq_max = std::max(iq_max, std::abs(s.iq_a));
  }
  DataRegion r;
  r.id_min = id_min;
  r.id_max = id_max;
  r.iq_min = iq_min;
  r.iq_max = iq_max;
  r.iq_signed_min = iq_signed_min;
  r.iq_signed_max = iq_signed_max;
  r.measured_iq = MeasuredIqOf(d);
  return r;
}

// A calibration of family f with this data's measured region.
Calibration CalibrationOf(const FitData& d, const DataRegion& r, const Family& f, const std::vector<double>& params,
                          const std::vector<double>& cov) {
  Calibration c(d.serial, f, params, cov, d.pole_pairs, d.rs_ohm, r.id_min, r.id_max, r.iq_min, r.iq_max);
  c.SetMeasuredIq(r.measured_iq.halves, r.measured_iq.lo_a, r.measured_iq.hi_a);
  return c;
}

// A regression spline of `spans` spans: its knots span the measured region
// (with id = 0, where psi_pm is defined) plus 5 % on each side.
Family SplineFamily(const DataRegion& r, int spans) {
  const double id_lo = std::min(r.id_min, 0.0), id_hi = std::max(r.id_max, 0.0);
  const double id_margin = 0.05 * std::max(id_hi - id_lo, 10.0);
  Family f;
  f.kind = Family::kSpline;
  f.spline.spans = spans;
  f.spline.id_lo_a = id_lo - id_margin;
  f.spline.id_hi_a = id_hi + id_margin;
  f.spline.iq_hi_a = 1.05 * std::max(r.iq_max, 10.0);
  return f;
}

// The mirrored layout's iq knots: kSmoothSpansIqHalf spans over the
// measured |iq| range plus 5 % on each side.
void SetMirroredRange(const DataRegion& r, Family* f) {
  const double m = 0.05 * std::max(r.iq_max - std::min(r.iq_min, 0.0), 10.0);
  f->spline.iq_lo_a = std::min(r.iq_min, 0.0) - m;
  f->spline.iq_hi_a = r.iq_max + m;
  f->spline.spans_q = kSmoothSpansIqHalf;
}

// Smoothing splines: 8 spans over the id range of the data box, smoothness
// chosen by GCV. "smooth" (symmetric) lays kSmoothSpansIqHalf spans over
// the measured |iq| range and mirrors it (SplineDomain::mirrored);
// "smooth-asym" spans the signed range the data cover with the same knot
// width, so that where both halves were measured it has the same
// resolution on each. Why not the folded layout (16 spans over [-Q, Q])
// any longer: it spent half its knots on the mirror image and has a knot
// at iq = 0, where the symmetry fixes W's odd derivatives; on the public
// bench set (data/real/baldor_eol, one half) it was 0.58 % RMS off the
// measured map over the motoring half, the mirrored layout 0.28 % (the
// asymmetric spline, which auto chose there before, 0.29 %, and 62 % off
// over the braking half). The folded layout at 32 spans reached 0.27 %
// too, but its smoothing spline then interpolated the lone 30 % outlier
// of Fit.GrossOutlierMovesNothing; docs/fitting.md has the span counts
// tried.
Family SmoothFamily(const DataRegion& r, bool symmetric) {
  Family f = SplineFamily(r, 8);
  f.spline.smoothing = true;
  f.spline.symmetric = symmetric;
  if (symmetric) {
    f.spline.mirrored = true;
    SetMirroredRange(r, &f);
  } else {
    Family ref = f;
    SetMirroredRange(r, &ref);
    const double width = (ref.spline.iq_hi_a - ref.spline.iq_lo_a) / ref.spline.spans_q;
    const double lo = std::min(r.iq_signed_min, 0.0), hi = std::max(r.iq_signed_max, 0.0);
    const double m = 0.05 * std::max(hi - lo, 10.0);
    f.spline.iq_lo_a = lo - m;
    f.spline.iq_hi_a = hi + m;
    const double spans = std::ceil((f.spline.iq_hi_a - f.spline.iq_lo_a) / width - 1e-9);
    f.spline.spans_q = static_cast<int>(std::clamp(spans, 8.0, 64.0));
  }
  return f;
}

// The smoothing splines' curvature weight (FitOptions).
double CurvatureWeightOf(const FitOptions& o) {
  const auto& mu = o.smoothing_curvature_weight;
  return mu && std::isfinite(*mu) && *mu >= 0 ? *mu : kSmoothingCurvatureWeight;
}

// The candidate families for `model_name` (ParseModelName's errors).
absl::StatusOr<std::vector<Family>> CandidateFamilies(const FitData& d, const DataRegion& r,
                                                      const std::string& model_name) {
  auto model = ParseModelName(model_name);
  if (!model.ok()) return model.status();
  using M = ModelName;
  const bool all = model->kind == M::kAuto;
  std::vector<Family> candidates;
  if (all || model->kind == M::kAnalytic) candidates.push_back({Family::kAnalytic, 0, {}});
  if (all || (model->kind == M::kPoly && model->n == 0)) {
    for (int deg = 3; deg <= 8; ++deg) candidates.push_back({Family::kPoly, deg, {}});
  } else if (model->kind == M::kPoly) {
    candidates.push_back({Family::kPoly, model->n, {}});
  }
  if (all || (model->kind == M::kSpline && model->n == 0)) {
    for (int spans = 1; spans <= 4; ++spans) candidates.push_back(SplineFamily(r, spans));
  } else if (model->kind == M::kSpline) {
    candidates.push_back(SplineFamily(r, model->n));
  }
  if (all || model->kind == M::kSmooth) candidates.push_back(SmoothFamily(r, true));
  // smooth-asym keeps psi_q(0, 0) = 0 and leaves psi_q(id, 0) to the data:
  // measured Ldq (psi_q(id, 0) is its integral along id from 0), flux rows
  // or flux nodes. Without any of them it is unobservable (any Ldq along
  // iq = 0 fits the Ldd/Lqq data equally): on a 6 x 6 grid of HF results
  // without Ldq, auto once chose it with psi_q(0, 0) = -18 mWb and the
  // torque and tables followed. And it is a candidate only when the data
  // measured both halves of the iq axis (MeasuredIqOf): on one half nothing
  // can show the map is not symmetric, and the asymmetric model's other
  // half is an extrapolation. Asked for by name it is still fitted; its
  // unmeasured half is then `extrapolated` (Calibration::RegionOf).
  bool ldq_seen = false;
  for (const auto& obs : d.inductances) ldq_seen |= obs.ldq_h.has_value();
  const bool psi_q_level_seen = ldq_seen || !d.steady_state.empty() || !d.fluxes.empty();
  const bool both_halves = r.measured_iq.halves == IqHalves::kBoth;
  if (model->kind == M::kSmoothAsym || ((all || model->kind == M::kSmooth) && psi_q_level_seen && both_halves)) {
    candidates.push_back(SmoothFamily(r, false));
  }
  return candidates;
}

// Each candidate solved (Cancelled when o.cancelled says so between two);
// a flexible family with fewer observations than parameters is skipped.
absl::StatusOr<std::vector<Solved>> SolveCandidates(const std::vector<Family>& candidates, const FitData& d,
                                                    const DataRegion& r,
                                                    const std::vector<Calibration::Box>& not_pd,
                                                    const FitOptions& o) {
  const int n_data = static_cast<int>(3 * d.inductances.size() + 3 * d.steady_state.size() + 2 * d.fluxes.size());
  // Every fit to make: a family, with a penalty's anisotropy kappa for the
  // smoothing splines. Each is independent of the others: solved in
  // parallel (fitting/parallel.h), then taken in candidate and grid order,
  // so the choice does not depend on the schedule.
  struct Task {
    size_t family;
    std::optional<double> kappa;
  };
  std::vector<Task> tasks;
  for (size_t c = 0; c < candidates.size(); ++c) {
    const Family& f = candidates[c];
    if (f.kind == Family::kSpline && f.spline.smoothing) {
      // May have more coefficients than observations: the penalty decides,
      // its weight lambda and its anisotropy kappa (SmoothingPenalty) both
      // by the restricted likelihood (Wood 2011: the marginal likelihood of
      // the smoothing parameters of a tensor-product smooth): for each
      // kappa on a grid of factors 9 (1/729 .. 729: a machine's two axes
      // saturate on current scales up to ~30x apart) lambda is chosen
      // (SolveLinear), and the kappa whose chosen fit has the best
      // likelihood wins. The likelihoods are comparable across kappa: the
      // penalties share their null space, so the marginal likelihood's
      // unpenalised part is common to all of them.
      if (o.smoothing_anisotropy_q && std::isfinite(*o.smoothing_anisotropy_q) && *o.smoothing_anisotropy_q > 0) {
        tasks.push_back({c, *o.smoothing_anisotropy_q});
      } else {
        for (int e = -3; e <= 3; ++e) tasks.push_back({c, std::pow(9.0, e)});
      }
      continue;
    }
    // A flexible family needs more observations than parameters.
    if (f.NumParams() + 2 > n_data) continue;
    tasks.push_back({c, std::nullopt});
  }
  // In rounds of one task per worker, the caller's cancellation polled on
  // this thread between rounds (the callback need not be thread-safe).
  std::vector<std::optional<Solved>> done(tasks.size());
  auto solve = [&](size_t t) {
    const Family& f = candidates[tasks[t].family];
    if (!tasks[t].kappa) {
      done[t] = Solve(f, d, o);
      return;
    }
    const Acceptable pd = [&](const std::vector<double>& params) {
      return CalibrationOf(d, r, f, params, {}).PhysicalOver(1.0, not_pd);
    };
    const Eigen::MatrixXd P = SmoothingPenalty(f, *tasks[t].kappa, CurvatureWeightOf(o));
    Solved s = Solve(f, d, o, &P, &pd);
    s.anisotropy_q = *tasks[t].kappa;
    done[t] = std::move(s);
  };
  const size_t round = static_cast<size_t>(std::max(1, WorkersFor(tasks.size())));
  for (size_t t0 = 0; t0 < tasks.size(); t0 += round) {
    if (o.cancelled && o.cancelled()) {
      return absl::CancelledError("fit: stopped between candidate models (cancelled by the caller)");
    }
    ParallelFor(std::min(round, tasks.size() - t0), [&](size_t k, int) { solve(t0 + k); });
  }
  std::vector<Solved> solved;
  for (size_t t = 0; t < tasks.size();) {
    // The smoothing spline's penalties: the kappa whose fit has the best
    // likelihood (grid order breaks ties).
    std::optional<Solved> chosen = std::move(done[t]);
    size_t u = t + 1;
    for (; u < tasks.size() && tasks[u].family == tasks[t].family; ++u) {
      auto& s = done[u];
      if ((s->usable && s->reml < chosen->reml) || !chosen->usable) chosen = std::move(s);
    }
    solved.push_back(std::move(*chosen));
    t = u;
  }
  return solved;
}

// The Report step: the selected fit's summary (modelled on
// ceres::Solver::Summary), its misfit over the inductances and flux nodes,
// the points it down-weighted, and every candidate's scores.
void Report(const FitData& d, const FitOptions& o, const std::vector<Solved>& solved,
            const std::vector<bool>& physical, const Solved* best, std::vector<std::string> excluded,
            int* down_weighted, Calibration* out) {
  Calibration& cal = *out;
  cal.summary.observations = best->n_obs;
  cal.summary.chi2 = best->chi2;
  cal.summary.bic = best->bic;
  cal.summary.termination = best->termination;
  cal.summary.usable = best->usable;
  cal.summary.smoothing_lambda = best->lambda;
  cal.summary.smoothing_anisotropy_q = best->lambda > 0 ? best->anisotropy_q : 1.0;
  cal.summary.smoothing_curvature_weight = best->lambda > 0 ? CurvatureWeightOf(o) : 0.0;
  cal.summary.effective_parameters = best->k_eff;
  double rel = 0;
  int nrel = 0;
  for (const auto& obs : d.inductances) {
    const auto L = PredictedInductance(cal, obs);
    rel += std::pow(L.ldd_h / obs.ldd_h - 1, 2) + std::pow(L.lqq_h / obs.lqq_h - 1, 2);
    nrel += 2;
  }
  cal.summary.rms_relative = nrel ? std::sqrt(rel / nrel) : 0.0;
  if (!d.fluxes.empty()) {
    std::vector<io::FluxMapPoint> nodes;
    for (const auto& f : d.fluxes) nodes.push_back({f.id_a, f.iq_a, f.psi_d_wb, f.psi_q_wb});
    const FluxNodeError e = FluxErrorOverNodes(cal, nodes);
    cal.summary.flux_nodes = e.nodes;
    cal.summary.flux_rms_relative = e.rms_relative;
    cal.summary.flux_max_relative = e.max_relative;
    cal.summary.flux_rms_wb = e.rms_wb;
    cal.summary.flux_max_wb = e.max_wb;
    cal.summary.flux_scale_wb = e.psi_scale_wb;
  }
  // Points beyond 3 robust scales of their stated sigma (a Huber weight of
  // a third or less at that scale), so a station sees which points did not
  // count fully.
  for (const auto& obs : d.inductances) {
    const HfPointMisfit m = MisfitOf(cal, obs, o);
    if (m.sigmas > 3.0 * o.robust_scale) {
      if (down_weighted != nullptr) ++*down_weighted;
      excluded.push_back(
          absl::StrFormat("hf point (id %.6g A, iq %.6g A): %s); down-weighted", obs.id_a, obs.iq_a, m.text));
    }
  }
  cal.summary.excluded = excluded;
  for (size_t k = 0; k < solved.size(); ++k) {
    const auto& s = solved[k];
    cal.summary.candidates.push_back(absl::StrFormat(
        "%s cv=%.4g bic=%.2f chi2=%.2f k=%.1f%s", s.family.Name(), s.cv, s.bic, s.chi2, s.k_eff,
        &s == best ? " (selected)" : (physical[k] ? "" : " (rejected: not positive definite where measured)")));
  }
}

}  // namespace

HfPointMisfit MisfitOf(const Calibration& cal, const InductanceObservation& obs, const FitOptions& o) {
  const auto L = PredictedInductance(cal, obs);
  const double sd = std::max(obs.ldd_h_std, o.relative_sigma_floor * std::abs(obs.ldd_h));
  const double sq = std::max(obs.lqq_h_std, o.relative_sigma_floor * std::abs(obs.lqq_h));
  const double zd = (L.ldd_h - obs.ldd_h) / sd, zq = (L.lqq_h - obs.lqq_h) / sq;
  HfPointMisfit m;
  m.sigmas = std::max(std::abs(zd), std::abs(zq));
  if (!std::isfinite(m.sigmas)) m.sigmas = 0;
  const bool d_worse = std::abs(zd) >= std::abs(zq);
  m.text = absl::StrFormat("%s off the surface by %.3g %% (%.0f sigma", d_worse ? "ldd_h" : "lqq_h",
                           100 * (d_worse ? L.ldd_h / obs.ldd_h - 1 : L.lqq_h / obs.lqq_h - 1), m.sigmas);
  return m;
}

absl::StatusOr<Calibration> FitScreened(const FitData& d, std::vector<std::string> excluded,
                                        const std::vector<Calibration::Box>& not_pd, const FitOptions& o,
                                        int* down_weighted, double* selected_cv) {
  if (d.inductances.size() < 3 && d.steady_state.size() < 3 && d.fluxes.size() < 3) {
    return absl::InvalidArgumentError(absl::StrCat(
        "field 'points': need at least 3 usable identified points to fit, got ", d.inductances.size(),
        excluded.empty() ? "" : absl::StrCat(" (", excluded.size(), " excluded: ", excluded[0], ")")));
  }
  const DataRegion region = RegionOf(d);
  auto candidates = CandidateFamilies(d, region, o.model);
  if (!candidates.ok()) return candidates.status();
  auto solved_or = SolveCandidates(*candidates, d, region, not_pd, o);
  if (!solved_or.ok()) return solved_or.status();
  const std::vector<Solved>& solved = *solved_or;
  if (solved.empty()) return absl::InvalidArgumentError("too few observations for any model family");
  // A candidate must be physical where it was measured: positive-definite
  // inductance over the measured region. (Widening the check by 50 %, as
  // before, vetoed good flexible fits of real machines for their quadratic
  // continuation beyond the knots and kept a 6 % fit of a measured PM-SyRM
  // map instead of a 0.8 % one; queries outside are flagged `extrapolated`.)
  // Among the physical ones the smallest generalised cross-validation score
  // wins: the estimate of the error at operating points not measured (tr H
  // effective parameters for the smoothing splines, k for the rest).
  std::vector<bool> physical(solved.size());
  const Solved* best = nullptr;
  for (size_t k = 0; k < solved.size(); ++k) {
    const auto& s = solved[k];
    physical[k] = CalibrationOf(d, region, s.family, s.params, {}).PhysicalOver(1.0, not_pd);
    if (s.usable && physical[k] && (best == nullptr || s.cv < best->cv)) best = &s;
  }
  if (best == nullptr) return absl::InternalError("no model family converged to a physical surface");
  Calibration cal = CalibrationOf(d, region, best->family, best->params, best->covariance);
  Report(d, o, solved, physical, best, std::move(excluded), down_weighted, &cal);
  if (selected_cv != nullptr) *selected_cv = best->cv;
  return cal;
}

}  // namespace fluxcal::fit::internal
