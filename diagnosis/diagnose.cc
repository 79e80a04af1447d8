#include "diagnosis/diagnose.h"

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cmath>
#include <complex>
#include <limits>
#include <numbers>
#include <optional>
#include <set>

#include <Eigen/Dense>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "ceres/ceres.h"
#include "identification/demod.h"
#include "identification/identify.h"
#include "fitting/fit.h"
#include "fitting/parallel.h"
#include "identification/inductance.h"
#include "simulation/effects.h"
#include "simulation/frames.h"
#include "simulation/magnetic_model.h"
#include "simulation/twin.h"
#include "diagnosis/effects/effect_term.h"
#include "diagnosis/internal.h"

namespace fluxcal::diag {

using namespace detail;   // the internals of diagnosis/internal.h


absl::StatusOr<fit::Calibration> DiagnosedCalibration(const DiagnosisReport& r, const fit::FitOptions& options) {
  if (r.corrected_data.inductances.empty() && r.corrected_data.steady_state.empty()) {
    return absl::FailedPreconditionError("diagnosis: no corrected data to fit (run Diagnose first)");
  }
  return fit::Fit(r.corrected_data, options);
}


namespace {
// Practical significance through the magnetics: the set's own surfaces are
// flexible, so a pattern an effect explains may already be followed by
// bending them, and the residual then hardly drops when the effect enters.
// What drops is the surfaces' flexibility: with the effect, the refit's
// criterion chooses them smoother (refit.cc, Solve). An effect that frees
// at least 10 % of their effective parameters (and at least 5) explains
// something the surfaces had to bend for (a 0.02 rad angle-sensor harmonic
// on the twin: 98 -> 76 effective parameters, the relative RMS 2 % lower).
bool RelaxesSurfaces(const FitOut& before, const FitOut& after) {
  return before.k_eff - after.k_eff >= std::max(5.0, 0.10 * before.k_eff);
}
}  // namespace

absl::StatusOr<DiagnosisReport> Diagnose(const io::RecordingSet& set, const DiagnoseOptions& opt) {
  const auto t0 = std::chrono::steady_clock::now();
  if (set.waveforms.empty()) {
    return absl::InvalidArgumentError("field 'points': diagnosis needs waveform points");
  }
  std::vector<ident::HfPointResult> ids;
  auto model = BuildModel(set, &ids);
  if (!model.ok()) return model.status();
  Model& m = *model;
  DiagnosisReport rep;
  rep.serial = set.manifest.serial;

  Params start(m);
  std::vector<Block> free = {kBase};
  FitOut base = Solve(m, start, free);
  rep.baseline = {"nominal", base.rms, base.bic, base.chi2};
  const auto z_before = Residuals(m, base.p);
  rep.mismatches = Locate(z_before, opt.mismatch_sigma);

  // Every effect's candidates the set can test (diagnosis/effects/), in
  // the report's order.
  std::vector<Candidate> cands;
  for (const auto& term : EffectTerms()) {
    if (opt.excluded_effects.count(std::string(term.effect)) > 0) continue;
    for (const auto& c : term.candidates) {
      if (term.testable == nullptr || term.testable(c, m)) cands.push_back(c);
    }
  }
  // The blocks a candidate frees (its own, and for a drift the mean beside it).
  auto blocks_of = [](const Candidate& c) {
    std::vector<Block> v = {c.block};
    if (c.also != kNumBlocks) v.push_back(c.also);
    return v;
  };
  auto without = [](std::vector<Block> free_blocks, const std::vector<Block>& gone) {
    std::vector<Block> out;
    for (Block x : free_blocks) {
      if (std::find(gone.begin(), gone.end(), x) == gone.end()) out.push_back(x);
    }
    return out;
  };
  // The current model refitted without one finding (its blocks held at
  // zero): the blocks left free and the fit.
  struct Without {
    std::vector<Block> free;
    FitOut fit;
  };
  auto refit_without = [&](const Candidate& c, const std::vector<Block>& free_now, const Params& p) {
    const std::vector<Block> gone = blocks_of(c);
    Without w{without(free_now, gone), {}};
    Params st = p;
    for (Block b : gone) std::fill(st.b[b].begin(), st.b[b].end(), 0.0);
    w.fit = Solve(m, st, w.free);
    return w;
  };
  FitOut current = base;
  const Model m_base = m;   // the baseline's magnetics (the replay "before")
  // Filled below: the candidate index per finding, and the findings' free
  // blocks.
  std::vector<size_t> accepted;
  // The magnetics with the effects found so far: the set's data freed of
  // them (CorrectedFitData) fitted again as `fluxcal fit` fits (its family
  // and smoothness chosen anew: a dead time bends the identified points
  // into a shape the plain fit smoothed for), then the joint model solved
  // again from there. Kept when it fits better.
  struct Refreshed {
    Model model;
    FitOut fit;
  };
  auto refreshed = [&](const Model& mm, const FitOut& ff, const std::vector<Block>& free_blocks) -> std::optional<Refreshed> {
    // The baseline's anisotropy kept (fit::FitOptions): the machine's axes
    // do not change with a finding, and it is one penalty instead of seven.
    fit::FitOptions fo;
    fo.smoothing_anisotropy_q = mm.surf_anisotropy_q;
    fo.smoothing_curvature_weight = mm.surf_curvature_weight;   // the baseline's penalty (observations.cc)
    fo.large_signal_hf = false;   // the joint model's HF prediction is small-signal (InitSurfaces)
    auto cal = fit::Fit(CorrectedFitData(set, mm, ff.p, ids), fo);
    if (!cal.ok()) return std::nullopt;
    Refreshed r{mm, {}};
    SetSurfaces(*cal, &r.model);
    Params p2 = ff.p;
    p2.b[kBase] = r.model.surf_init;
    r.fit = Solve(r.model, p2, free_blocks);
    if (!r.fit.ok) return std::nullopt;
    return r;
  };
  auto refresh = [&](const std::vector<Block>& free_blocks) {
    auto r = refreshed(m, current, free_blocks);
    if (r && r->fit.chi2 < current.chi2) {
      m = std::move(r->model);
      current = r->fit;
    }
  };
  std::vector<std::string> model_name = {"nominal"};
  std::vector<bool> used(cands.size(), false);
  // A drift no longer significant beside the other findings is a mean
  // shift after all: its plain variant (the drift's `also` block alone)
  // takes its place where that is still material and significant, instead
  // of the finding going as a whole. (A magnet flux 6 % low with a torque
  // loss: the drift took part of the loss's speed pattern in the first
  // round; once the loss was in, the drift was insignificant and the
  // backward round dropped the magnet flux with it.)
  auto demote_drift = [&](size_t a) {
    const Candidate& c = cands[accepted[a]];
    if (c.also == kNumBlocks || Significance(c, current, m) >= opt.parameter_sigma) return false;
    size_t plain = cands.size();
    for (size_t k = 0; k < cands.size(); ++k) {
      if (cands[k].effect == c.effect && cands[k].block == c.also && cands[k].also == kNumBlocks) plain = k;
    }
    if (plain == cands.size()) return false;
    Params st = current.p;
    std::fill(st.b[c.block].begin(), st.b[c.block].end(), 0.0);
    const std::vector<Block> plain_free = without(free, {c.block});
    const FitOut f = Solve(m, st, plain_free);
    if (!f.ok || Significance(cands[plain], f, m) < opt.parameter_sigma) return false;
    free = plain_free;
    accepted[a] = plain;
    const Finding fd = Describe(cands[plain], m, f);
    rep.findings[a].parameters = fd.parameters;
    rep.findings[a].parameter_std = fd.parameter_std;
    current = f;
    return true;
  };
  // Stepwise selection: forward rounds (best candidate by BIC among those
  // that pass every test) until none qualifies, then one backward round:
  // a finding that is no longer material or significant in the joint fit,
  // or whose removal (the others refitted) costs less than the BIC
  // threshold, is dropped -- an effect accepted early can turn out to be a
  // stand-in for a pair accepted later (a constant angle offset for the
  // speed-proportional rotation of a delay at mid speed). Dropped
  // candidates are not tried again, so this ends.
  for (int pass = 0; pass < 4; ++pass) {
  while (true) {
    int best = -1;
    FitOut best_fit;
    std::optional<Model> best_model;   // set when the accepted fit refitted the surfaces
    // The current model's residuals, once per round (candidates compare to them).
    const auto z_current = Residuals(m, current.p);
    std::vector<RejectedCandidate> round_rejected;
    // Each candidate's joint refit from the current model, independent of
    // the others: solved in parallel, then judged in catalogue order.
    std::vector<size_t> open;
    for (size_t c = 0; c < cands.size(); ++c) {
      if (used[c]) continue;
      if (std::find(free.begin(), free.end(), cands[c].block) != free.end()) continue;
      open.push_back(c);
    }
    auto trial_of = [&](size_t c) {
      std::vector<Block> trial = free;
      for (Block b : blocks_of(cands[c])) {
        if (std::find(trial.begin(), trial.end(), b) == trial.end()) trial.push_back(b);
      }
      return trial;
    };
    std::vector<FitOut> trial_fit(cands.size());
    const bool stopped = ParallelForModels(
        open.size(), m,
        [&](size_t k, Model& mw) {
          const size_t c = open[k];
          if (cands[c].block == kHarm) mw.harm_order = cands[c].order;
          Params st = current.p;
          if (cands[c].block == kHarm) st.b[kHarm][0] = 0.0;
          // A candidate's surfaces are never rougher than the model it is
          // compared with (internal.h, Model::surf_lambda_floor), or than
          // the set's own calibration where that model is stiffer: a
          // baseline that cannot fit an effect takes its misfit for noise
          // and its scan of the penalty weight goes stiff (a synchronous
          // reluctance machine with Rs 23 % high: 64 times the
          // calibration's weight, 22 effective parameters), and at that
          // floor the surfaces could not follow the HF points beside the
          // right effect (chi^2 19180 on 256 rows with Rs, 12681 with a
          // DC-link sense gain, which was named first; docs/diagnosis.md).
          mw.surf_lambda_floor = std::min(current.lambda, m.surf_lambda);
          trial_fit[c] = Solve(mw, st, trial_of(c));
        },
        opt.cancelled);
    if (stopped) {
      return absl::CancelledError("diagnosis: stopped between candidate refits (cancelled by the caller)");
    }
    for (size_t c : open) {
      if (cands[c].block == kHarm) m.harm_order = cands[c].order;
      const std::vector<Block> trial = trial_of(c);
      FitOut f = std::move(trial_fit[c]);
      std::optional<Model> cand_model;
      if (!f.ok) continue;
      const double dbic = f.bic - current.bic;
      const double sig = Significance(cands[c], f, m);
      std::string why;
      if (dbic > -opt.bic_threshold) {
        why = absl::StrFormat("BIC improves by %.1f, not more than %.0f", -dbic, opt.bic_threshold);
      } else if (sig < opt.parameter_sigma) {
        why = sig == 0.0 ? (Plausible(cands[c], f, m)
                                ? "its fitted size is below the catalogue's materiality floor"
                                : "its fitted value is physically implausible (below the catalogue's plausible range)")
                         : absl::StrFormat("its parameter is %.1f standard deviations from neutral, below %.0f", sig,
                                           opt.parameter_sigma);
      } else if (!PracticallySignificant(z_current, Residuals(m, f.p), current.rms, f.rms, opt) &&
                 !RelaxesSurfaces(current, f)) {
        // The surfaces may still hold what the effect explains: refitted
        // as `fluxcal fit` would from the data freed of it (its family and
        // smoothness chosen anew), do they relax or fit better?
        auto rf = refreshed(m, f, trial);
        if (rf && rf->fit.bic - current.bic < -opt.bic_threshold &&
            (RelaxesSurfaces(current, rf->fit) ||
             PracticallySignificant(z_current, Residuals(rf->model, rf->fit.p), current.rms, rf->fit.rms, opt))) {
          f = rf->fit;
          cand_model = std::move(rf->model);
        } else {
          why = "it lowers neither the residual RMS by 10 % nor half of a located region's excess, nor lets the "
                "surfaces be smoother";
        }
      }
      if (!why.empty()) {
        std::string name = cands[c].effect;
        if (cands[c].block == kHarm) name += absl::StrFormat(" (order %d)", cands[c].order);
        round_rejected.push_back({name, why, dbic, sig});
        continue;
      }
      if (best < 0 || f.bic < best_fit.bic) {
        best = static_cast<int>(c);
        best_fit = f;
        best_model = cand_model;
      }
    }
    if (best < 0) {
      // The best rejected candidates of the last round, by BIC.
      std::sort(round_rejected.begin(), round_rejected.end(),
                [](const RejectedCandidate& a, const RejectedCandidate& b) { return a.delta_bic < b.delta_bic; });
      if (round_rejected.size() > 3) round_rejected.resize(3);
      rep.rejected = round_rejected;
      break;
    }
    used[best] = true;
    if (best_model) m = std::move(*best_model);
    if (cands[best].block == kHarm) m.harm_order = cands[best].order;
    for (Block b : blocks_of(cands[best])) {
      if (std::find(free.begin(), free.end(), b) == free.end()) free.push_back(b);
    }
    Finding fd = Describe(cands[best], m, best_fit);
    fd.residual_rms_before = current.rms;
    fd.residual_rms_after = best_fit.rms;
    fd.delta_bic = best_fit.bic - current.bic;
    // A refinement of a finding already made (a drift beside the mean)
    // takes its place: one finding per effect.
    size_t same = rep.findings.size();
    for (size_t a = 0; a < rep.findings.size(); ++a) {
      if (rep.findings[a].effect == cands[best].effect) same = a;
    }
    if (same < rep.findings.size()) {
      fd.residual_rms_before = rep.findings[same].residual_rms_before;
      fd.delta_bic += rep.findings[same].delta_bic;
      rep.findings[same] = fd;
      accepted[same] = static_cast<size_t>(best);
    } else {
      rep.findings.push_back(fd);
      model_name.push_back(cands[best].effect);
      accepted.push_back(static_cast<size_t>(best));
    }
    for (size_t c = 0; c < cands.size(); ++c) {
      // The plain variant is done when its drift is in.
      if (cands[c].effect == cands[best].effect && cands[c].block == cands[best].also) used[c] = true;
    }
    current = best_fit;
    refresh(free);
  }
  for (size_t a = 0; a < accepted.size(); ++a) demote_drift(a);
  int drop = -1;
  FitOut drop_fit;
  double drop_cost = opt.bic_threshold;
  for (size_t a = 0; accepted.size() >= 2 && a < accepted.size(); ++a) {
    const Without w = refit_without(cands[accepted[a]], free, current.p);
    const FitOut& f = w.fit;
    if (!f.ok) continue;
    // A finding no longer material or significant beside the others goes
    // first (cost -inf); otherwise the one whose removal costs least.
    const double cost = Significance(cands[accepted[a]], current, m) < opt.parameter_sigma
                            ? -1e300 : f.bic - current.bic;
    if (cost < drop_cost) { drop = static_cast<int>(a); drop_cost = cost; drop_fit = f; }
  }
  if (drop < 0) break;
  free = without(free, blocks_of(cands[accepted[drop]]));
  rep.findings.erase(rep.findings.begin() + drop);
  model_name.erase(model_name.begin() + 1 + drop);
  accepted.erase(accepted.begin() + drop);
  current = drop_fit;
  }
  // The inverter's soft sign. Dead time and switch threshold act per phase
  // as tanh(i_x / i_th) (the paper's eq. (9) is its hard-sign limit); i_th,
  // the current below which the switching transient no longer completes
  // within the dead time, is a property of the inverter (its output
  // capacitance, the switching speed), not a constant: the independent
  // generator's is 1.35 A. It enters nonlinearly, so it is profiled once the
  // effects are chosen: the final model refitted on a grid of i_th a
  // factor 2 apart over 0.0625..4 A, then a golden-section search in
  // ln i_th between the best grid point's neighbours, and kept as one more
  // parameter by the rule that admits an effect (BIC lower by more than
  // bic_threshold, counting it). Where the data do not pin it (little
  // current near zero), the model keeps kIth.
  const bool soft_sign = std::any_of(free.begin(), free.end(), [](Block b) { return b == kDead || b == kVth; });
  if (soft_sign && opt.profile_soft_sign) {
    FitOut best = current;
    double best_ith = m.ith_a;
    // -2 ln(likelihood) up to a constant, the noise variance profiled out
    // (the BIC's first term): n ln chi2 of the final model at i_th = e^x.
    auto solve_at = [&](double x, Model* mi) {
      SetSoftSignCurrent(set, std::exp(x), mi);
      return Solve(*mi, current.p, free);
    };
    auto take = [&](double x, const FitOut& f) {
      if (!f.ok) return std::numeric_limits<double>::infinity();
      if (f.bic < best.bic) { best = f; best_ith = std::exp(x); }
      return f.bic;
    };
    auto profile = [&](double x) {
      Model mi = m;
      return take(x, solve_at(x, &mi));
    };
    const double step = std::log(2.0);
    std::vector<double> xs, ls;
    for (int j = 0; j <= 6; ++j) xs.push_back(std::log(0.0625) + j * step);
    // The grid's refits are independent: in parallel, then taken in order.
    std::vector<FitOut> grid(xs.size());
    const bool stopped = ParallelForModels(
        xs.size(), m, [&](size_t j, Model& mw) { grid[j] = solve_at(xs[j], &mw); }, opt.cancelled);
    if (stopped) {
      return absl::CancelledError("diagnosis: stopped while profiling the soft-sign current (cancelled by the caller)");
    }
    for (size_t j = 0; j < xs.size(); ++j) ls.push_back(take(xs[j], grid[j]));
    const size_t i = static_cast<size_t>(std::min_element(ls.begin(), ls.end()) - ls.begin());
    double a = xs[i > 0 ? i - 1 : i], b = xs[i + 1 < xs.size() ? i + 1 : i];
    constexpr double kGolden = 0.6180339887498949;
    double c = b - kGolden * (b - a), d = a + kGolden * (b - a), lc = profile(c), ld = profile(d);
    for (int it = 0; it < 9; ++it) {   // bracket 0.62^9 = 1.3 % of 2 steps: ~1.8 % in i_th
      if (lc < ld) { b = d; d = c; ld = lc; c = b - kGolden * (b - a); lc = profile(c); }
      else { a = c; c = d; lc = ld; d = a + kGolden * (b - a); ld = profile(d); }
    }
    if (best_ith != m.ith_a && best.bic + std::log(std::max(1, best.n)) < current.bic - opt.bic_threshold) {
      // sd(ln i_th) from the profile's curvature: n ln chi2 rises by 1 at
      // one standard deviation, sd = sqrt(2 / L'').
      const double x0 = std::log(best_ith), h = 0.05;
      const FitOut keep = best;
      const double l0 = profile(x0), curv = (profile(x0 + h) - 2 * l0 + profile(x0 - h)) / (h * h);
      best = keep;
      best_ith = std::exp(x0);
      SetSoftSignCurrent(set, best_ith, &m);
      m.ith_estimated = true;
      m.ith_std_a = curv > 0 ? best_ith * std::sqrt(2.0 / curv) : 0.0;
      current = best;
    }
  }
  // A finding the final model no longer needs goes: once the soft sign is
  // profiled (or a later effect is accepted) an earlier one may shrink below
  // its materiality floor or its significance (a 0.04 % DC-link gain taken
  // in beside a dead time at the assumed i_th, on real magnetics).
  for (bool dropped = true; dropped && !accepted.empty();) {
    dropped = false;
    for (size_t a = 0; a < accepted.size(); ++a) {
      if (cands[accepted[a]].block == kHarm) m.harm_order = cands[accepted[a]].order;
      if (demote_drift(a)) {
        dropped = true;
        break;
      }
      if (Significance(cands[accepted[a]], current, m) >= opt.parameter_sigma) continue;
      const Without w = refit_without(cands[accepted[a]], free, current.p);
      const std::vector<Block>& trial = w.free;
      const FitOut& f = w.fit;
      if (!f.ok) continue;
      free = trial;
      rep.findings.erase(rep.findings.begin() + static_cast<long>(a));
      model_name.erase(model_name.begin() + 1 + static_cast<long>(a));
      accepted.erase(accepted.begin() + static_cast<long>(a));
      current = f;
      dropped = true;
      break;
    }
  }
  // Parameters of every finding from the final joint fit (an effect's
  // value moves when a later one is accepted beside it).
  for (size_t a = 0; a < accepted.size(); ++a) {
    if (cands[accepted[a]].block == kHarm) m.harm_order = cands[accepted[a]].order;
    const Finding fd = Describe(cands[accepted[a]], m, current);
    rep.findings[a].parameters = fd.parameters;
    rep.findings[a].parameter_std = fd.parameter_std;
  }
  std::string name = "nominal";
  for (size_t k = 1; k < model_name.size(); ++k) name += "+" + model_name[k];
  rep.final_model = {name, current.rms, current.bic, current.chi2};
  const auto z_after = Residuals(m, current.p);
  rep.remaining = Locate(z_after, opt.mismatch_sigma);
  for (size_t k = 0; k < z_before.size(); ++k) {
    rep.residuals.push_back({z_before[k].point, z_before[k].signal, z_before[k].id_a, z_before[k].iq_a,
                             z_before[k].speed_rpm, std::sqrt(z_before[k].z2 / z_before[k].dof),
                             std::sqrt(z_after[k].z2 / z_after[k].dof)});
  }
  const auto ptr = current.p.Ptrs();
  for (size_t k = 0; k < ids.size(); ++k) {
    if (!std::isfinite(ids[k].ld_h) || !std::isfinite(ids[k].id_a)) continue;
    CorrectedPoint cp;
    cp.point = ids[k].point;
    cp.id_a = ids[k].id_a;
    cp.iq_a = ids[k].iq_a;
    m.Inductance(ptr.data(), cp.id_a, cp.iq_a, &cp.ldd_h, &cp.lqq_h, &cp.ldq_h);
    cp.ldd_h_identified = ids[k].ld_h;
    cp.lqq_h_identified = ids[k].lq_h;
    rep.corrected.push_back(cp);
  }
  rep.corrected_data = CorrectedFitData(set, m, current.p, ids);
  // A located region is explained when the accepted findings removed at
  // least 90 % of its chi^2 excess over its degrees of freedom; what stays
  // significant is still listed in `remaining`. A region that the findings
  // made significant (not located before) also leaves the verdict partial:
  // the final model is then wrong somewhere the nominal one was not.
  bool all_explained = true;
  for (const auto& after : rep.remaining) {
    double before_sigma = 0;
    for (const auto& before : rep.mismatches) {
      if (after.signal == before.signal && after.where == before.where) before_sigma = before.significance_sigma;
    }
    if (after.significance_sigma > 0.1 * before_sigma) all_explained = false;
  }
  // Honesty (docs/diagnosis.md): the final model, refitted without one
  // observable class at a time, must predict that class. A located region
  // of the class whose prediction error stays significant means the
  // findings fit the data without being the physics that made them.
  if (!rep.findings.empty()) {
    // The held DC voltages at the second DC-link voltage are held out as a
    // region when the set has them: an inverter-voltage explanation fitted
    // at one Udc must predict them (a dead time standing in for a switch
    // threshold predicts them Udc2/Udc1 too large or small). Not when both
    // dead_time and inverter_voltage_drop are in the model: without those
    // points the two are one signature and the check has nothing to test.
    const bool both_inverter = std::find(free.begin(), free.end(), kDead) != free.end() &&
                               std::find(free.begin(), free.end(), kVth) != free.end();
    const bool has_second = std::any_of(m.dc.begin(), m.dc.end(), [](const DcObs& d) { return d.second_udc; });
    std::vector<int> kinds = {kHfKind, kDcKind, kSsKind, kTorqueKind};
    if (has_second && !both_inverter) kinds.push_back(kDcSecondUdcKind);
    std::set<std::string> second_points;
    for (const auto& d : m.dc) if (d.second_udc) second_points.insert(d.point);
    // Significance of the excess chi^2 over the second-Udc points' held DC
    // voltages, (chi2 - k) / sqrt(2k), as RegionStat::Sigma.
    auto second_sigma = [&](const std::vector<Z>& zs) {
      double chi2 = 0;
      int k = 0;
      for (const auto& z : zs) {
        if (z.signal == "dc_voltage" && second_points.count(z.point)) { chi2 += z.z2; k += z.dof; }
      }
      return k ? (chi2 - k) / std::sqrt(2.0 * k) : 0.0;
    };
    kinds.erase(std::remove_if(kinds.begin(), kinds.end(),
                               [&](int kind) {
                                 return kind == kHfKind ? m.hf.empty()
                                        : kind == kDcKind || kind == kDcSecondUdcKind ? m.dc.empty()
                                        : kind == kSsKind ? m.ss.empty()
                                                          : std::none_of(m.ss.begin(), m.ss.end(),
                                                                         [](const SsObs& o) { return o.has_torque; });
                               }),
                kinds.end());
    // Each class's held-out refit, independent of the others: in parallel.
    std::vector<FitOut> held(kinds.size());
    ParallelForModels(kinds.size(), m, [&](size_t k, Model& mw) {
      const int kind = kinds[k];
      // Held-out HF: the surfaces are what the HF phasors measure, so they
      // stay as fitted; the question is whether the effects, refitted from
      // the other classes, predict the phasors (an effect seen in the HF
      // only keeps its value and passes; one that stands in for physics the
      // DC voltages contradict does not).
      std::vector<Block> refit = free;
      if (kind == kHfKind) {
        refit.erase(std::remove_if(refit.begin(), refit.end(), [](Block b) { return b == kBase; }),
                    refit.end());
      }
      // The surfaces' smoothness: the full fit's (with a class left out,
      // the BIC chooses it on less data, and the prediction would test
      // that choice, not the effects) and the one the remaining classes
      // choose; the prediction is judged with the better of the two, as
      // the check is of the effects.
      const double own_lambda = mw.surf_lambda;
      if (current.lambda > 0) mw.surf_lambda = current.lambda;
      FitOut f = Solve(mw, current.p, refit, kind, /*choose_lambda=*/false);
      mw.surf_lambda = own_lambda;
      if (kind != kHfKind && mw.surf_lambda > 0) {
        const FitOut g = Solve(mw, current.p, refit, kind);
        if (g.ok && (!f.ok || RelativeRmsOf(mw, g.p, kind) < RelativeRmsOf(mw, f.p, kind))) f = g;
      }
      held[k] = std::move(f);
    });
    for (size_t k = 0; k < kinds.size(); ++k) {
      const int kind = kinds[k];
      const FitOut& f = held[k];
      if (!f.ok) continue;
      HeldOutCheck h;
      h.signal = KindSignal(kind);
      const auto z = Residuals(m, f.p);
      double located = 0;
      if (kind == kHfKind) {
        // The HF phasors pin some effects (a delay, an HF resistance) far
        // better than the other classes, so their prediction from the other
        // classes alone can be poor and still consistent. The test is
        // Hausman's: the effect parameters refitted without the HF against
        // those of the full fit, each difference in units of the standard
        // deviation of the difference, sqrt(sd_without^2 - sd_full^2)
        // (the full fit being the efficient one). An effect that stands in
        // for physics the other classes contradict moves by many of those.
        const double worst = ParameterShiftSigma(f, current, free);
        h.significance_sigma = worst;
        h.residual_rms = RelativeRmsOf(m, f.p, kind);
        // A parameter distance, judged as parameters are (parameter_sigma).
        h.passed = worst < opt.parameter_sigma;
        if (!h.passed) all_explained = false;
        rep.held_out.push_back(h);
        continue;
      } else if (kind == kDcSecondUdcKind) {
        h.significance_sigma = std::max(0.0, second_sigma(z));
        // Its residual RMS as the dc class's (relative to the set's DC scale).
        double s2 = 0;
        int n = 0;
        const auto ptr = f.p.Ptrs();
        for (const auto& o : m.dc) {
          if (!o.second_udc) continue;
          s2 += std::norm(o.u - m.PredictDc(ptr.data(), o)) / (m.dc_scale_v * m.dc_scale_v);
          ++n;
        }
        h.residual_rms = n ? std::sqrt(s2 / n) : 0.0;
        located = std::max(0.0, second_sigma(z_before));
      } else {
        for (const auto& r : RegionStats(z)) {
          if (r.signal == h.signal && r.k > 0) h.significance_sigma = std::max(h.significance_sigma, r.Sigma());
        }
        h.residual_rms = RelativeRmsOf(m, f.p, kind);
        for (const auto& mm : rep.mismatches) {
          if (mm.signal == h.signal) located = std::max(located, mm.significance_sigma);
        }
      }
      // Without a class, the parameters it pinned down are known less well,
      // so a class whose located mismatch was gross may keep a little of it:
      // the prediction passes below `heldout_sigma`, or when it removes at
      // least 98 % of the class's located significance (e.g. a dead time
      // fitted without the held DC voltages predicts them to 65 sigma of
      // 39566).
      h.passed = h.significance_sigma < std::max(opt.heldout_sigma, opt.heldout_fraction * located);
      if (!h.passed && (kind == kSsKind || kind == kTorqueKind) && FoundWithout(f, free, opt.parameter_sigma)) {
        // The steady-state voltages and the torque measure the flux
        // itself: without them the surfaces are the HF inductances
        // integrated, which on a machine of strong cross saturation miss
        // the flux by percents (docs/fitting.md, "HF results alone"), and
        // the prediction tests that integration, not the effects. Where
        // every effect is found without the class, the effects are judged
        // as for the HF phasors: their parameters must not move (Hausman).
        // An effect only this class witnesses (iron loss at speed, a
        // torque loss) is not found without it and keeps the prediction
        // test.
        h.parameter_shift_sigma = ParameterShiftSigma(f, current, free);
        // A move below every parameter's materiality floor changes no
        // decision, however many standard deviations of the difference it
        // is: where the class adds little to what the others know, that
        // difference's deviation is a sliver of each estimate's, and
        // wherever the surfaces cannot follow the machine the class pulls
        // by that much: a 0.03 rad angle offset on the measured PM-SyRM's
        // raw map interpolated node to node (a 10x dip of Ldd near one
        // corner) moved by 0.0007 rad, 1.2 of its standard deviations and
        // 9 of the difference's, a sixth of its 0.0044 rad floor, and
        // failed the set (docs/diagnosis.md). A stand-in's parameters move
        // by their size.
        std::vector<Candidate> found;
        for (size_t a : accepted) found.push_back(cands[a]);
        h.parameter_shift_material = MaterialMove(found, m, f, current);
        h.passed = h.parameter_shift_sigma < opt.parameter_sigma || !h.parameter_shift_material;
      }
      if (!h.passed) all_explained = false;
      rep.held_out.push_back(h);
    }
  }
  // Waveform evidence through the twin (docs/diagnosis.md, "The
  // waveforms"): every test replayed with the baseline and with the final
  // model, the residual's spectrum at multiples of 50 Hz up to +-2.5 kHz,
  // and the lines the model does not reproduce located: against the
  // baseline (mismatches) and against the final model (remaining).
  bool waveform_remaining = false;
  if (opt.waveform_replay) {
    for (int f = -50; f <= 50; ++f) rep.spectrum_hz.push_back(50.0 * f);
    const double f_inj = set.manifest.injection ? set.manifest.injection->frequency_hz : 0.0;
    // The two replays are independent (each builds its own surface model).
    std::vector<absl::StatusOr<std::vector<sim::ReplayPoint>>> replays(2);
    fit::ParallelFor(2, [&](size_t k, int) {
      replays[k] = k == 0 ? ReplayModel(set, m_base, base.p, m_base.harm_order)
                          : ReplayModel(set, m, current.p, m.harm_order);
    });
    auto before = std::move(replays[0]);
    auto after = std::move(replays[1]);
    if (before.ok()) LeaveOutUnheldPoints(ids, &*before);
    if (after.ok()) LeaveOutUnheldPoints(ids, &*after);
    if (before.ok()) {
      rep.waveform_rms_before_a = ReplaySpectrum(set, *before, rep.spectrum_hz, &rep.spectrum_before_a);
      for (auto& w : WaveformMismatches(AnalyseWaveforms(set, *before, m.pole_pairs), m.pole_pairs, f_inj,
                                        opt.mismatch_sigma)) {
        rep.mismatches.push_back(std::move(w));
      }
    }
    if (after.ok()) {
      rep.waveform_rms_after_a = ReplaySpectrum(set, *after, rep.spectrum_hz, &rep.spectrum_after_a);
      for (auto& w : WaveformMismatches(AnalyseWaveforms(set, *after, m.pole_pairs), m.pole_pairs, f_inj,
                                        opt.mismatch_sigma)) {
        rep.remaining.push_back(std::move(w));
        waveform_remaining = true;
      }
    }
    auto significant = [&](const std::vector<double>& sp) {
      std::vector<double> sorted = sp, out;
      if (sorted.empty()) return out;
      std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
      const double floor = sorted[sorted.size() / 2];
      for (size_t k = 0; k < sp.size(); ++k) if (sp[k] > 10.0 * floor) out.push_back(rep.spectrum_hz[k]);
      return out;
    };
    rep.significant_hz_before = significant(rep.spectrum_before_a);
    rep.significant_hz_after = significant(rep.spectrum_after_a);
  }
  AttachHypotheses(&rep.mismatches, m.pole_pairs);
  AttachHypotheses(&rep.remaining, m.pole_pairs);
  // A waveform component the final model does not reproduce is a mismatch
  // no finding explains: never `explained`.
  if (waveform_remaining) all_explained = false;
  if (rep.findings.empty()) {
    rep.verdict = rep.mismatches.empty() && !waveform_remaining ? "no_mismatch" : "unexplained";
  } else {
    rep.verdict = all_explained ? "explained" : "partly_explained";
  }
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return rep;
}

}  // namespace fluxcal::diag
