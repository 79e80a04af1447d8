#include "fitting/screen.h"

#include <algorithm>
#include <cmath>
#include <iterator>
#include <utility>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "fitting/problem.h"
#include "physics/torque.h"

namespace fluxcal::fit::internal {
namespace {

double Median(std::vector<double> v) {
  const size_t h = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + h, v.end());
  const double upper = v[h];
  if (v.size() % 2) return upper;
  return 0.5 * (upper + *std::max_element(v.begin(), v.begin() + h));
}

// The measured values of one axis next to x on each side (x itself at an
// edge): the extent of the grid cells around a point at x.
std::pair<double, double> Neighbours(const std::vector<double>& sorted_axis, double x) {
  auto hi = std::upper_bound(sorted_axis.begin(), sorted_axis.end(), x);
  auto lo = std::lower_bound(sorted_axis.begin(), sorted_axis.end(), x);
  return {lo == sorted_axis.begin() ? x : *std::prev(lo), hi == sorted_axis.end() ? x : *hi};
}

// A steady-state row is two measurements of one operating point: its
// voltages give the flux, psi_d = (u_q - Rs i_q) / w_e and psi_q =
// -(u_d - Rs i_d) / w_e (SteadyStateFlux), hence an air-gap torque
// T_u = 3/2 p (psi_d i_q - psi_q i_d) (recording-format.md's convention),
// and the transducer measures T. A row whose current controller did not
// hold the point (a limit cycle at speed, a runaway caught mid-way) averages
// voltages and currents of different states and the two disagree grossly.
// Such a row is excluded: within the region its flux is taken as exact to
// 0.2 %, and on a twin IPMSM one such row (T = -12 N m, T_u = -0.6 N m at
// -59 A, 4 A) bent the whole surface 19 % off: every other residual grew,
// the robust scale (the residuals' spread) grew with them and took the row
// back in. Measured against the rows' own agreement, not against zero: an
// uncompensated dead time or a transducer gain moves every row alike (the
// independent dead-time example: z from -24 to 0, median -11, the farthest
// row 4 robust spreads out), which is the diagnosis' signature to find,
// not a row to drop. A row is out when
// its z = (T - T_u) / sigma lies more than kRowTorqueOutlier robust spreads
// (1.4826 MAD, at least 1) from the median of the rows that report torque;
// with fewer than three such rows there is no consensus to measure against.
void ScreenRowsByTorque(FitData& d, std::vector<size_t>* input_index, std::vector<std::string>* excluded) {
  struct RowZ {
    size_t at;
    double z, t_nm, t_u_nm;
  };
  std::vector<RowZ> rows;
  const double current_scale = DataCurrentScaleA(d);
  for (size_t k = 0; k < d.steady_state.size(); ++k) {
    const auto& s = d.steady_state[k];
    if (!s.torque_nm) continue;
    double pd, pq;
    SteadyStateFlux(s, d.pole_pairs, d.rs_ohm, d.f_pwm_hz, &pd, &pq);
    const double t_u = physics::ElectromagneticTorque(d.pole_pairs, pd, pq, s.id_a, s.iq_a);
    const double s_t_u = 1.5 * d.pole_pairs * std::hypot(s.id_a, s.iq_a) *
                         RowSigmaWb(s, d.pole_pairs, current_scale, pd, pq);
    const double sigma = std::hypot(RowTorqueSigmaNm(*s.torque_nm), s_t_u);
    const double z = (*s.torque_nm - t_u) / sigma;
    if (std::isfinite(z)) rows.push_back({k, z, *s.torque_nm, t_u});
  }
  if (rows.size() < 3) return;
  std::vector<double> z;
  for (const auto& r : rows) z.push_back(r.z);
  const auto [mid, spread] = RowConsensus(z);
  std::vector<bool> drop(d.steady_state.size(), false);
  for (const auto& r : rows) {
    if (std::abs(r.z - mid) <= kRowTorqueOutlier * spread) continue;
    drop[r.at] = true;
    const auto& s = d.steady_state[r.at];
    excluded->push_back(absl::StrFormat(
        "steady-state row %d (id %.6g A, iq %.6g A, %.0f rpm): its voltages give %.4g N m of torque at its "
        "current, the bench measured %.4g N m (%.0f robust spreads from the other rows' agreement): not a "
        "steady state; excluded",
        (*input_index)[r.at] + 1, s.id_a, s.iq_a, s.speed_rpm, r.t_u_nm, r.t_nm, std::abs(r.z - mid) / spread));
  }
  size_t w = 0;
  for (size_t k = 0; k < d.steady_state.size(); ++k) {
    if (drop[k]) continue;
    d.steady_state[w] = d.steady_state[k];
    (*input_index)[w] = (*input_index)[k];
    ++w;
  }
  d.steady_state.resize(w);
  input_index->resize(w);
}

// Rows the bench says it did not hold (the recording's extension columns,
// docs/recording-format.md). The voltages of such a row average the flux
// over whatever the current did, and the row can agree with its own torque
// (both are averages over the same excursion): on the fixed-gain bench the
// synchronous reluctance twin's rows at 1500-2000 rpm, 52-100 A, read psi_q
// 3-7 % low with their torque in agreement, the torque screen kept them, and
// the fit was 19.8 % off (RealMaps.SelfConsistentBadRowsOnAMistunedBench).
//  - A share of the window at the voltage limit or with the controller
//    clamped: for that time the current was not controlled. On the twin's
//    tuned benches every row reads 0 (RealMaps.TwinTraitMotorsEndToEnd,
//    OtherKindsEndToEnd); the rows that did not hold read 0.30-1.0.
//    kRowLimitedShareMax = 5 % lies between and lets a row at the edge of
//    the voltage range touch the limit now and then (a few periods in a
//    hundred).
//  - A current ripple beyond kRowRippleMax = 1/3 of the row's current
//    (RowRelativeRipple): then the current's excursion of three RMS
//    reaches zero, the row averages the flux across the origin, and the
//    expansion about the mean current that RowSigmaWb's widening rests on
//    no longer holds (its estimate there, 1/2 r^2 = 5.6 % of the flux, is
//    eleven times the row's model sigma of 0.5 % anyway). Tuned benches
//    read 0.2-0.5 % (the current sensors' noise and resolution); rows of
//    the fixed-gain bench that the bench otherwise held 1-30 %, with flux
//    errors of 0.4 % at most, and a row at 65 % was 3 % off.
// Below those limits a rippled row stays with its sigma widened (RowSigmaWb)
// and is listed when that widening reaches kRowRippleListed.
void ScreenRowsTheBenchDidNotHold(FitData& d, std::vector<size_t>* input_index,
                                  std::vector<std::string>* excluded) {
  const double current_scale = DataCurrentScaleA(d);
  size_t w = 0;
  for (size_t k = 0; k < d.steady_state.size(); ++k) {
    const auto& s = d.steady_state[k];
    const std::string where = absl::StrFormat("steady-state row %d (id %.6g A, iq %.6g A, %.0f rpm)",
                                              (*input_index)[k] + 1, s.id_a, s.iq_a, s.speed_rpm);
    const double r = RowRelativeRipple(s, current_scale);
    std::string why;
    if (s.voltage_limited_share && *s.voltage_limited_share > kRowLimitedShareMax) {
      why = absl::StrFormat("the modulator was at its voltage limit for %.3g %% of its averaging window (more than "
                            "%.3g %%)", 100 * *s.voltage_limited_share, 100 * kRowLimitedShareMax);
    } else if (s.controller_saturated_share && *s.controller_saturated_share > kRowLimitedShareMax) {
      why = absl::StrFormat("the current controller was clamped for %.3g %% of its averaging window (more than "
                            "%.3g %%)", 100 * *s.controller_saturated_share, 100 * kRowLimitedShareMax);
    } else if (r > kRowRippleMax) {
      why = absl::StrFormat("its current ripple, %.4g A RMS, is %.3g %% of its current (more than %.3g %%)",
                            *s.current_ripple_a, 100 * r, 100 * kRowRippleMax);
    }
    if (!why.empty()) {
      excluded->push_back(absl::StrCat(where, ": ", why, ": the bench did not hold the row; excluded"));
      continue;
    }
    double pd, pq;
    SteadyStateFlux(s, d.pole_pairs, d.rs_ohm, d.f_pwm_hz, &pd, &pq);
    const double widened = RowSigmaWb(s, d.pole_pairs, current_scale, pd, pq) /
                           RowFluxSigmaWb(s.speed_rpm, d.pole_pairs, pd, pq);
    if (std::isfinite(widened) && widened >= kRowRippleListed) {
      excluded->push_back(absl::StrFormat(
          "%s: its current ripple, %.4g A RMS, is %.3g %% of its current: flux sigma x%.3g; down-weighted", where,
          *s.current_ripple_a, 100 * r, widened));
    }
    d.steady_state[w] = s;
    (*input_index)[w] = (*input_index)[k];
    ++w;
  }
  d.steady_state.resize(w);
  input_index->resize(w);
}

}  // namespace

Consensus RowConsensus(const std::vector<double>& z) {
  Consensus c;
  c.mid = Median(z);
  std::vector<double> dev;
  for (double v : z) dev.push_back(std::abs(v - c.mid));
  c.spread = std::max(1.0, 1.4826 * Median(dev));
  return c;
}

// Bad points are data, not fatal: what cannot be an observation of a
// physical machine is left out with its reason, the rest is fitted.
//  - a non-finite current or value, or a non-positive Ldd / Lqq. A real map
//    can fall in id near zero current: the point is left out (its sigma,
//    relative to the value, has no scale) but believed, so the cells around
//    it, out to the neighbouring measured id and |iq| on each side, are
//    returned in `not_pd` and the fit is not required positive definite
//    there. Required everywhere, it vetoed every smoothing spline that
//    followed the neighbours into the dip, and a 4-span spline missed the
//    map by 0.67 % RMS where the smoothing spline gives 0.15 %
//    (RealMaps.FluxErrorOnEveryDraw, the negative-slope map);
//  - a standard error that is not finite, negative, or as large as the
//    value itself (nothing to learn from it);
// Duplicates and conflicting values stay: the robust loss down-weights the
// one that disagrees with its neighbours, and Fit lists it afterwards.
FitData Screen(const FitData& in, std::vector<std::string>* excluded, std::vector<Calibration::Box>* not_pd,
               std::vector<size_t>* row_index) {
  FitData d = in;
  d.inductances.clear();
  d.steady_state.clear();
  d.fluxes.clear();
  std::vector<double> ids, iqs;   // the measured axes (distinct, sorted)
  for (const auto& o : in.inductances) {
    if (std::isfinite(o.id_a) && std::isfinite(o.iq_a)) {
      ids.push_back(o.id_a);
      iqs.push_back(std::abs(o.iq_a));
    }
  }
  for (auto* v : {&ids, &iqs}) {
    std::sort(v->begin(), v->end());
    v->erase(std::unique(v->begin(), v->end()), v->end());
  }
  for (size_t k = 0; k < in.inductances.size(); ++k) {
    const auto& o = in.inductances[k];
    const std::string where = absl::StrFormat("hf point %d (id %.6g A, iq %.6g A)", k + 1, o.id_a, o.iq_a);
    std::string why;
    if (!std::isfinite(o.id_a) || !std::isfinite(o.iq_a)) why = "current not finite";
    else if (!std::isfinite(o.ldd_h) || !(o.ldd_h > 0)) why = absl::StrFormat("ldd_h = %.6g H is not positive", o.ldd_h);
    else if (!std::isfinite(o.lqq_h) || !(o.lqq_h > 0)) why = absl::StrFormat("lqq_h = %.6g H is not positive", o.lqq_h);
    else if (o.ldq_h && !std::isfinite(*o.ldq_h)) why = "ldq_h not finite";
    else if (!std::isfinite(o.ldd_h_std + o.lqq_h_std + o.ldq_h_std) || o.ldd_h_std < 0 || o.lqq_h_std < 0 ||
             o.ldq_h_std < 0 || o.ldd_h_std >= o.ldd_h || o.lqq_h_std >= o.lqq_h) {
      why = "standard error not finite, negative or as large as the value";
    }
    const bool non_positive = std::isfinite(o.id_a) && std::isfinite(o.iq_a) &&
                              ((std::isfinite(o.ldd_h) && o.ldd_h <= 0) || (std::isfinite(o.lqq_h) && o.lqq_h <= 0));
    if (non_positive) {
      const auto [d_lo, d_hi] = Neighbours(ids, o.id_a);
      const auto [q_lo, q_hi] = Neighbours(iqs, std::abs(o.iq_a));
      not_pd->push_back({d_lo, d_hi, q_lo, q_hi});
      why += absl::StrFormat(" (the surface is not required positive definite over id %.6g..%.6g A, |iq| "
                             "%.6g..%.6g A around it)", d_lo, d_hi, q_lo, q_hi);
    }
    if (!why.empty()) {
      excluded->push_back(absl::StrCat(where, ": ", why, "; excluded"));
      continue;
    }
    d.inductances.push_back(o);
  }
  // The region the HF points measured (with 10 % of its span, at least
  // 2 A, around it): a steady-state row far outside it is a run whose
  // current controller lost the operating point (voltage limit, a runaway
  // at speed), not a flux anchor; kept, it would also stretch the spline
  // knots over hundreds of amperes nobody measured.
  double lo_d = 1e300, hi_d = -1e300, lo_q = 1e300, hi_q = -1e300;
  for (const auto& o : d.inductances) {
    lo_d = std::min(lo_d, o.id_a); hi_d = std::max(hi_d, o.id_a);
    lo_q = std::min(lo_q, std::abs(o.iq_a)); hi_q = std::max(hi_q, std::abs(o.iq_a));
  }
  const bool have_box = d.inductances.size() >= 3;
  const double md = std::max(2.0, 0.1 * (hi_d - lo_d)), mq = std::max(2.0, 0.1 * (hi_q - lo_q));
  std::vector<size_t> kept_rows;   // input index of each row in d.steady_state
  for (size_t k = 0; k < in.steady_state.size(); ++k) {
    const auto& s = in.steady_state[k];
    const bool ok = std::isfinite(s.id_a) && std::isfinite(s.iq_a) && std::isfinite(s.ud_ref_v) &&
                    std::isfinite(s.uq_ref_v) && std::isfinite(s.speed_rpm) && std::abs(s.speed_rpm) > 1.0 &&
                    (!s.torque_nm || std::isfinite(*s.torque_nm));
    if (!ok) {
      excluded->push_back(absl::StrFormat("steady-state row %d (id %.6g A, iq %.6g A): a value is not finite or "
                                          "the speed is below 1 rpm; excluded", k + 1, s.id_a, s.iq_a));
      continue;
    }
    if (have_box && (s.id_a < lo_d - md || s.id_a > hi_d + md || std::abs(s.iq_a) < lo_q - mq ||
                     std::abs(s.iq_a) > hi_q + mq)) {
      excluded->push_back(absl::StrFormat(
          "steady-state row %d (id %.6g A, iq %.6g A, %.0f rpm): outside the region the HF points measured "
          "(id %.6g..%.6g A, |iq| %.6g..%.6g A); excluded", k + 1, s.id_a, s.iq_a, s.speed_rpm, lo_d, hi_d, lo_q,
          hi_q));
      continue;
    }
    d.steady_state.push_back(s);
    kept_rows.push_back(k);
  }
  // The flux nodes before the rows' own screens: the ripple's current
  // scale counts them (DataCurrentScaleA).
  for (size_t k = 0; k < in.fluxes.size(); ++k) {
    const auto& f = in.fluxes[k];
    if (!std::isfinite(f.id_a + f.iq_a + f.psi_d_wb + f.psi_q_wb) || !(f.psi_std_wb > 0)) {
      excluded->push_back(absl::StrFormat("flux node %d (id %.6g A, iq %.6g A): not finite or no positive "
                                          "standard deviation; excluded", k + 1, f.id_a, f.iq_a));
      continue;
    }
    d.fluxes.push_back(f);
  }
  ScreenRowsTheBenchDidNotHold(d, &kept_rows, excluded);
  ScreenRowsByTorque(d, &kept_rows, excluded);
  *row_index = kept_rows;
  return d;
}

double RowMisfit(const Calibration& cal, const FitData& d, const SteadyStateObservation& s) {
  double pd, pq;
  SteadyStateFlux(s, d.pole_pairs, d.rs_ohm, d.f_pwm_hz, &pd, &pq);
  const auto f = cal.Flux(s.id_a, s.iq_a);
  const double sigma = RowSigmaWb(s, d.pole_pairs, DataCurrentScaleA(d), pd, pq);
  return std::max(std::abs(f.psi_d_wb - pd), std::abs(f.psi_q_wb - pq)) / sigma;
}

}  // namespace fluxcal::fit::internal
