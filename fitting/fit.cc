// Fit (fitting/fit.h): screen, fit, and leave out the steady-state rows
// the fit of everything else contradicts. The steps live in their own
// files: problem.cc (Build: the residuals, *_residual.h), solve.cc and
// solve_linear.cc (Solve), select.cc (the candidate families, selection
// and Report), screen.cc (the row screens), fit_data.cc (the adapters).
#include "fitting/fit.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <tuple>
#include <utility>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "fitting/large_signal.h"
#include "fitting/screen.h"
#include "fitting/select.h"

namespace fluxcal::fit {

using internal::FitScreened;
using internal::kRowTorqueOutlier;
using internal::RowConsensus;
using internal::RowMisfit;
using internal::Screen;

absl::StatusOr<ModelName> ParseModelName(const std::string& name) {
  using M = ModelName;
  if (name == "auto") return M{M::kAuto, 0};
  if (name == "analytic") return M{M::kAnalytic, 0};
  if (name == "poly") return M{M::kPoly, 0};
  if (name == "spline") return M{M::kSpline, 0};
  if (name == "smooth") return M{M::kSmooth, 0};
  if (name == "smooth-asym") return M{M::kSmoothAsym, 0};
  int n = 0;
  if (name.rfind("poly", 0) == 0 && absl::SimpleAtoi(name.substr(4), &n) && n >= 2 && n <= 10) {
    return M{M::kPoly, n};
  }
  if (name.rfind("spline", 0) == 0 && absl::SimpleAtoi(name.substr(6), &n) && n >= 1 && n <= 8) {
    return M{M::kSpline, n};
  }
  return absl::InvalidArgumentError(absl::StrCat("flag --model: expected auto, analytic, poly, polyN (N 2..10), "
                                                 "spline, splineN (N 1..8), smooth or smooth-asym, got '", name, "'"));
}

namespace {

// A machine without magnets (psi_pm stated 0) has no magnet axis to put d
// on; fluxcal's d is then the low-permeance axis, where a PM-assisted
// machine would carry its magnets, so that Lqq > Ldd as for every other
// machine it fits (docs/recording-format.md, "Machines without magnets").
// The reluctance-machine literature and SyR-e put d on the high-permeance
// axis instead. Data in that frame fit as well as any, but every table
// built on them searches the wrong quadrant (no torque where the MTPA
// should be), so they are refused, saying how to rotate them. The axes are
// judged on the HF points (Ldd against Lqq), else on the flux nodes and
// steady-state rows (the apparent psi_d / id against psi_q / iq, taken
// where both currents are at least a tenth of the data's largest).
absl::Status CheckReluctanceAxes(const FitData& d) {
  if (!d.psi_pm_prior_wb || *d.psi_pm_prior_wb != 0.0) return absl::OkStatus();
  int high_d = 0, judged = 0;
  for (const auto& o : d.inductances) {
    if (!(o.ldd_h > 0) || !(o.lqq_h > 0)) continue;
    ++judged;
    high_d += o.ldd_h > o.lqq_h;
  }
  std::string what = "identified points";
  if (judged == 0) {
    what = "flux nodes and steady-state rows";
    std::vector<std::array<double, 4>> nodes;   // id, iq, psi_d, psi_q
    for (const auto& f : d.fluxes) nodes.push_back({f.id_a, f.iq_a, f.psi_d_wb, f.psi_q_wb});
    for (const auto& s : d.steady_state) {
      double pd, pq;
      SteadyStateFlux(s, d.pole_pairs, d.rs_ohm, d.f_pwm_hz, &pd, &pq);
      nodes.push_back({s.id_a, s.iq_a, pd, pq});
    }
    double scale = 0;
    for (const auto& n : nodes) scale = std::max({scale, std::abs(n[0]), std::abs(n[1])});
    for (const auto& n : nodes) {
      if (std::abs(n[0]) < 0.1 * scale || std::abs(n[1]) < 0.1 * scale) continue;
      const double ld = n[2] / n[0], lq = n[3] / n[1];
      if (!(ld > 0) || !(lq > 0)) continue;
      ++judged;
      high_d += ld > lq;
    }
  }
  if (judged < 3 || 2 * high_d <= judged) return absl::OkStatus();
  return absl::InvalidArgumentError(absl::StrFormat(
      "motor.psi_pm_wb: 0 (a machine without magnets), and d is the high-inductance axis at %d of %d %s: the data "
      "are in the reluctance-machine frame (d on the high-permeance axis, as SyR-e's), fluxcal's d is the "
      "low-permeance axis (docs/recording-format.md, \"Machines without magnets\"). Rotate them by -90 electrical "
      "degrees: id = -iq', iq = id', psi_d = -psi_q', psi_q = psi_d' (theta_e = theta_e' - pi/2 for waveforms; "
      "a flux map: --convention syre)",
      high_d, judged, what));
}

// A gross HF outlier: a point the selected fit misses by more than this
// many robust spreads of the points' misfits (the rows' kRowTorqueOutlier,
// applied to the HF points). Huber's loss bounds its pull on the surface,
// but not its share of the selection score: its cost 2 c |r| - c^2 is
// about the same large sum for every candidate, and the score n chi^2 /
// (n - k)^2 then prefers the candidate with the fewest parameters whatever
// the other points say (a point 30 % off, 115 sigma, on a twin set: poly4
// instead of spline2, every other point moved 0.4 %).
constexpr double kHfGrossOutlierSpreads = 20.0;

// The HF points `cal` misses by more than kHfGrossOutlierSpreads robust
// spreads (largest first, at most a tenth of the points), each with its
// line for the calibration's excluded list.
std::vector<std::pair<size_t, std::string>> GrossHfOutliers(const Calibration& cal, const FitData& d,
                                                             const FitOptions& o) {
  std::vector<double> z(d.inductances.size());
  std::vector<std::string> what(d.inductances.size());
  for (size_t k = 0; k < d.inductances.size(); ++k) {
    const internal::HfPointMisfit m = internal::MisfitOf(cal, d.inductances[k], o);
    z[k] = m.sigmas;
    what[k] = m.text;
  }
  std::vector<std::pair<size_t, std::string>> out;
  if (z.size() < 10) return out;
  std::vector<double> sorted = z;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<long>(sorted.size() / 2), sorted.end());
  const double spread = std::max(1.0, 1.4826 * sorted[sorted.size() / 2]);
  std::vector<std::pair<double, size_t>> far;
  for (size_t k = 0; k < z.size(); ++k)
    if (z[k] > kHfGrossOutlierSpreads * spread) far.push_back({z[k], k});
  std::sort(far.rbegin(), far.rend());
  if (far.size() > z.size() / 10) far.resize(z.size() / 10);
  for (const auto& [zk, k] : far) {
    out.push_back({k, absl::StrFormat("hf point (id %.6g A, iq %.6g A): %s, %.0f robust spreads of the points' misfit "
                                      "beyond %.0f): excluded, the fit redone without it",
                                      d.inductances[k].id_a, d.inductances[k].iq_a, what[k], zk / spread,
                                      kHfGrossOutlierSpreads)});
  }
  return out;
}

}  // namespace

// Screen, fit, and then the rows the torque screen could not judge. A row
// without torque that averaged a limit cycle carries a flux that nothing
// else in the data supports, and within the region it is taken as exact to
// 0.2 %: on a twin IPMSM bench one such row (psi 0.002 / 0.004 Wb where the
// motor has 0.012 / 0.016) bent the surface 19 % off and twelve consistent
// HF points were down-weighted at 200-300 sigma instead. So when the fit
// down-weighted anything, or a row misfits by more than 10 sigma, each row
// (the 12 worst) is predicted by the fit of everything else (leave one
// out) and the one whose prediction error lies more than kRowTorqueOutlier
// robust spreads beyond the rows' median is excluded and the fit redone;
// twice at most. A model error that every row shares (a dead time, an Rs)
// moves them alike and excludes none.
absl::StatusOr<Calibration> Fit(const FitData& input, const FitOptions& o) {
  if (input.pole_pairs < 1 || input.pole_pairs > 100) {
    return absl::InvalidArgumentError(absl::StrCat(
        "pole_pairs: ", input.pole_pairs == 0 ? std::string("unknown") : absl::StrCat(input.pole_pairs),
        " (1..100 required: the manifest's motor.pole_pairs or --pole-pairs; torque and speed depend on them)"));
  }
  if (absl::Status axes = CheckReluctanceAxes(input); !axes.ok()) return axes;
  std::vector<std::string> excluded;
  std::vector<Calibration::Box> not_pd;
  std::vector<size_t> row_index;
  FitData d = Screen(input, &excluded, &not_pd, &row_index);
  // One box per distinct cell: the check visits every box at each of its
  // 169 nodes for every candidate lambda, and a file of many non-positive
  // points on one grid would otherwise repeat the same cells.
  auto key = [](const Calibration::Box& b) { return std::tie(b.id_lo_a, b.id_hi_a, b.abs_iq_lo_a, b.abs_iq_hi_a); };
  std::sort(not_pd.begin(), not_pd.end(), [&](const auto& a, const auto& b) { return key(a) < key(b); });
  not_pd.erase(std::unique(not_pd.begin(), not_pd.end(), [&](const auto& a, const auto& b) { return key(a) == key(b); }),
               not_pd.end());
  int down_weighted = 0;
  double cv_small = 0;
  auto cal = FitScreened(d, excluded, not_pd, o, &down_weighted, &cv_small);
  // Gross HF outliers out, once (kHfGrossOutlierSpreads says why).
  if (cal.ok()) {
    const auto gross = GrossHfOutliers(*cal, d, o);
    if (!gross.empty()) {
      std::vector<bool> drop(d.inductances.size(), false);
      for (const auto& [k, line] : gross) {
        drop[k] = true;
        excluded.push_back(line);
      }
      std::vector<InductanceObservation> kept;
      for (size_t k = 0; k < d.inductances.size(); ++k)
        if (!drop[k]) kept.push_back(d.inductances[k]);
      d.inductances = std::move(kept);
      down_weighted = 0;
      cal = FitScreened(d, excluded, not_pd, o, &down_weighted, &cv_small);
    }
  }
  // Large-signal HF (docs/fitting.md): the points whose injection is known
  // predicted over their orbits on this first pass's surfaces, and fitted
  // again. Which forward model the data support is chosen as the family
  // is, by the lower cross-validation score: a machine whose injection
  // sweeps a knee needs many more effective parameters to follow its
  // identified values with Jacobians (a bridge-knee twin: 93 against 59,
  // score 1.43 against 0.96). The large-signal fit must lower the score by
  // more than kLargeSignalScoreMargin: its orbits come from the first
  // pass's surface, whose curvature (on which the orbit's correction
  // depends) is least certain where the orbits see little of it, and
  // there the two scores tie within a few per cent (measured: the knee
  // machines of the twin 7-42 % lower, the independent example sets and
  // the twin's default motor -1 to +5 %; docs/fitting.md). Or the orbits
  // must change most points' predictions by more than their noise (median
  // above kLargeSignalEvidentSigma): then the describing function is the
  // measurement's own equation beyond the data's precision, and a score
  // that a small-signal surface can match by bending is no argument
  // against it (the twin's knee machines: medians 1.8-13 sigma, scores
  // up to 13 % higher once the rotating points were consistent; the
  // independent example sets 0.3-0.7 sigma).
  std::string hf_model;
  if (cal.ok() && o.large_signal_hf) {
    FitData large = d;
    double median_sigmas = 0;
    const int orbits = internal::AttachHfOrbits(*cal, o.relative_sigma_floor, &large, &median_sigmas);
    if (orbits > 0) {
      int dw = 0;
      double cv_large = 0;
      auto cal_large = FitScreened(large, excluded, not_pd, o, &dw, &cv_large);
      const bool evident = median_sigmas > internal::kLargeSignalEvidentSigma;
      const bool take =
          cal_large.ok() && (evident || cv_large < (1.0 - internal::kLargeSignalScoreMargin) * cv_small);
      hf_model = absl::StrFormat(
          "hf model: large-signal (describing function over the orbits of %d of %zu points, median change %.2g sigma) "
          "cv=%.4g, small-signal cv=%.4g: %s kept",
          orbits, d.inductances.size(), median_sigmas, cal_large.ok() ? cv_large : std::nan(""), cv_small,
          take ? "large-signal" : "small-signal");
      if (take) {
        d = std::move(large);
        cal = std::move(cal_large);
        down_weighted = dw;
      }
    }
  }
  constexpr int kMaxRowsOut = 2;
  constexpr size_t kMaxRowsTried = 12;
  constexpr double kRowMisfitTrigger = 10.0;
  for (int round = 0; round < kMaxRowsOut && cal.ok() && d.steady_state.size() >= 3; ++round) {
    std::vector<std::pair<double, size_t>> misfit;
    for (size_t k = 0; k < d.steady_state.size(); ++k) misfit.push_back({RowMisfit(*cal, d, d.steady_state[k]), k});
    std::sort(misfit.rbegin(), misfit.rend());
    if (down_weighted == 0 && misfit.front().first <= kRowMisfitTrigger) break;
    if (misfit.size() > kMaxRowsTried) misfit.resize(kMaxRowsTried);
    struct LeftOut {
      size_t row;
      double z;
      Calibration fit;   // of all data but the row
      int down_weighted;
    };
    std::vector<LeftOut> loo;
    // The leave-one-out fits keep the full fit's smoothing anisotropy (the
    // machine's axes do not change with one row less; lambda is still
    // chosen anew): one penalty per fit instead of the grid's seven, up to
    // 12 fits a round.
    FitOptions loo_options = o;
    if (!loo_options.smoothing_anisotropy_q && cal->summary.smoothing_lambda > 0) {
      loo_options.smoothing_anisotropy_q = cal->summary.smoothing_anisotropy_q;
    }
    for (const auto& [in_fit, k] : misfit) {
      if (o.cancelled && o.cancelled()) {
        return absl::CancelledError("fit: stopped between leave-one-row-out fits (cancelled by the caller)");
      }
      FitData without = d;
      without.steady_state.erase(without.steady_state.begin() + static_cast<long>(k));
      int dw = 0;
      auto f = FitScreened(without, excluded, not_pd, loo_options, &dw);
      if (!f.ok()) continue;
      const double z = RowMisfit(*f, d, d.steady_state[k]);
      loo.push_back({k, z, std::move(*f), dw});
    }
    if (loo.size() < 3) break;
    std::vector<double> z;
    for (const auto& l : loo) z.push_back(l.z);
    const auto [mid, spread] = RowConsensus(z);
    auto worst = std::max_element(loo.begin(), loo.end(), [](const LeftOut& a, const LeftOut& b) { return a.z < b.z; });
    if (worst->z - mid <= kRowTorqueOutlier * spread) break;
    const size_t k = worst->row;
    const auto& s = d.steady_state[k];
    double pd, pq;
    SteadyStateFlux(s, d.pole_pairs, d.rs_ohm, d.f_pwm_hz, &pd, &pq);
    const auto f = worst->fit.Flux(s.id_a, s.iq_a);
    const std::string why = absl::StrFormat(
        "steady-state row %d (id %.6g A, iq %.6g A, %.0f rpm): its voltages give psi %.4g, %.4g Wb, the fit of "
        "all other data %.4g, %.4g Wb (%.0f sigma, %.0f robust spreads beyond the other rows' agreement): not a "
        "steady state; excluded",
        row_index[k] + 1, s.id_a, s.iq_a, s.speed_rpm, pd, pq, f.psi_d_wb, f.psi_q_wb, worst->z,
        (worst->z - mid) / spread);
    // The fit without the row is the new fit; its list gains the reason
    // ahead of its own down-weighted points.
    auto& list = worst->fit.summary.excluded;
    list.insert(list.begin() + static_cast<long>(excluded.size()), why);
    excluded.push_back(why);
    d.steady_state.erase(d.steady_state.begin() + static_cast<long>(k));
    row_index.erase(row_index.begin() + static_cast<long>(k));
    down_weighted = worst->down_weighted;
    cal = std::move(worst->fit);
  }
  // The facts the data source stated about the machine and drive.
  if (cal.ok()) {
    if (!hf_model.empty()) cal->summary.candidates.push_back(hf_model);
    cal->set_udc_v(input.udc_v);
    cal->set_psi_pm_nominal_wb(input.psi_pm_prior_wb);
    cal->set_psi_pm_temp_coeff_per_k(input.psi_pm_temp_coeff_per_k);
    // The magnet temperature of the flux map: that of the observations
    // the kept fit used (d, after the screens and the rows left out).
    if (const auto ref = MagnetReferenceOf(d)) cal->set_magnet_reference(ref->mean_c, ref->spread_k);
  }
  return cal;
}

}  // namespace fluxcal::fit
