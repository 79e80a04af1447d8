// The operating-point solver (tables/tables.h, tables/internal_solver.h):
// torque and voltage from flux linkage, the least-current point of a torque
// request under the current and voltage limits, and the limit torque.
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>

#include "physics/torque.h"
#include "tables/internal_numeric.h"
#include "tables/internal_solver.h"
#include "tables/tables.h"

namespace fluxcal::tables {

using internal::FwNewton;
using internal::SolveIqForTorque;
using internal::LimitTorque;
using internal::MinimiseScalar;
using internal::MtpvLimit;
using internal::RowLoci;
using internal::SolveWithMax;
using internal::TrySolve;
using internal::VoltageFromFlux;

double MachineLimits::UMaxV() const {
  return udc_v ? modulation_limit * *udc_v / std::sqrt(3.0) : std::numeric_limits<double>::quiet_NaN();
}

double TorqueNm(const sim::MagneticModel& m, int pp, double id, double iq, double temperature_c) {
  const auto f = m.Flux(id, iq, temperature_c);
  return physics::ElectromagneticTorque(pp, f.psi_d_wb, f.psi_q_wb, id, iq);
}

double VoltageV(const sim::MagneticModel& m, const MachineLimits& lim, double id, double iq, double we) {
  if (!lim.rs_ohm) return std::numeric_limits<double>::quiet_NaN();
  return internal::VoltageFromFlux(lim, id, iq, we, m.Flux(id, iq, lim.temperature_c));
}

namespace internal {

bool SolveIqForTorque(const sim::MagneticModel& m, const MachineLimits& lim, double id, double t,
                      double s, double* iq_out, double iq_guess_a, sim::FluxLinkage* flux_out, bool lazy_bracket,
                      double* slope_out) {
  const double target = std::abs(t);
  double lo = 0.0, hi = std::max(10.0, lim.i_max_a);
  auto torque = [&](double iq) { return s * TorqueNm(m, lim.pole_pairs, id, s * iq, lim.temperature_c); };
  // The bracket's upper end: grown until the torque there reaches the
  // target (false if it never does). `lazy_bracket` with a start inside the
  // first [lo, hi]: grown only when hi is needed (a Newton step at or
  // beyond it, a bisection, or the bracket's width), so a converging warm
  // start skips that surface evaluation; the iterates are the same as
  // when it is grown first, where the torque is monotone in iq.
  int grow = 0;
  double t_hi = 0.0;
  bool hi_known = false;
  auto grow_hi = [&] {
    while ((t_hi = torque(hi)) < target) {
      hi *= 2;
      if (++grow > 8) return false;
    }
    hi_known = true;
    return true;
  };
  const bool warm = iq_guess_a > lo && iq_guess_a < hi;
  if (!(lazy_bracket && warm) && !grow_hi()) return false;
  double iq = iq_guess_a > lo && iq_guess_a < hi
                  ? iq_guess_a
                  : std::clamp(target / std::max(1e-9, t_hi) * hi, lo, hi);
  // The flux at the last iq evaluated (the root when the loop ends there).
  sim::FluxLinkage F;
  sim::DifferentialInductance L;
  bool f_at_iq = false;
  for (int it = 0; it < 60; ++it) {
    // One surface evaluation per iteration serves both T and dT/diq (a
    // spline calibration shares the basis between flux and inductance).
    m.FluxAndInductance(id, s * iq, lim.temperature_c, &F, &L);
    f_at_iq = true;
    const double f = s * physics::ElectromagneticTorque(lim.pole_pairs, F.psi_d_wb, F.psi_q_wb, id, s * iq) - target;
    if (std::abs(f) < 1e-10 * (1.0 + target)) break;
    if (f > 0) {
      hi = iq;
      hi_known = true;
    } else {
      lo = iq;
    }
    const double d = physics::TorqueSlopeIq(lim.pole_pairs, F.psi_d_wb, L.ldq_h, L.lqq_h, id, s * iq);
    double next = iq - f / (d > 1e-12 ? d : 1e-12);
    if (!hi_known && !(next > lo && next < hi && hi - lo >= 1e-12) && !grow_hi()) return false;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (hi - lo < 1e-12) break;
    iq = next;
    f_at_iq = false;
  }
  *iq_out = s * iq;
  if (flux_out != nullptr) *flux_out = f_at_iq ? F : m.Flux(id, s * iq, lim.temperature_c);
  if (slope_out != nullptr) {
    if (!f_at_iq) m.FluxAndInductance(id, s * iq, lim.temperature_c, &F, &L);
    // Along the locus d iq / d id = -T_d / T_q.
    const double t_d = 1.5 * lim.pole_pairs * (L.ldd_h * s * iq - F.psi_q_wb - L.ldq_h * id);
    const double t_q = physics::TorqueSlopeIq(lim.pole_pairs, F.psi_d_wb, L.ldq_h, L.lqq_h, id, s * iq);
    *slope_out = -t_d / t_q;
  }
  return true;
}

}  // namespace internal


namespace {

// Whether TrySolve's current-limit test (|i| <= i_max (1 + 1e-9)) decides
// the same at FwNewton's root as at the robust solve's, given `r`, the
// root's |i| minus that threshold. The robust solve ends within its bracket
// (2e-9 A in id) of the same root, which moves |i| by that times the slope
// of |i| along the locus (of order one where a cell meets the current
// limit); 1e-8 A from the threshold the answers agree. (A clamped point
// at a corner of the limits, where the limit torque's point is on both the
// current and the voltage limit, lies ~1e-9 of i_max inside: e.g. 2e-8 A at
// 18 A.)
bool CurrentLimitSettled(double r) { return std::abs(r) > 1e-8; }

// TrySolve's field-weakening step by FwNewton, from the row's last
// voltage-limited cell and, failing that, from the MTPA point (id_mtpa,
// iq_mtpa). 1: solved, *op set; 0: the point lies beyond the current limit
// (TrySolve's false); -1: not settled, solve robustly (also where
// CurrentLimitSettled is not).
int FastFieldWeakening(const sim::MagneticModel& m, const MachineLimits& lim, double t, double we, double s,
                       double id_mtpa, double iq_mtpa, RowLoci* row, OperatingPoint* op) {
  double id = 0.0, iq = 0.0;
  sim::FluxLinkage f;
  const bool ok = (row->warm && FwNewton(m, lim, t, we, s, row->warm_id, row->warm_iq, id_mtpa, &id, &iq, &f)) ||
                  FwNewton(m, lim, t, we, s, id_mtpa, iq_mtpa, id_mtpa, &id, &iq, &f);
  if (!ok) return -1;
  const double r = std::hypot(id, iq) - lim.i_max_a * (1 + 1e-9);
  if (!CurrentLimitSettled(r)) return -1;
  row->warm = true;
  row->warm_id = id;
  row->warm_iq = iq;
  if (r > 0) return 0;
  op->id_a = id;
  op->iq_a = iq;
  op->torque_nm = physics::ElectromagneticTorque(lim.pole_pairs, f.psi_d_wb, f.psi_q_wb, id, iq);   // TorqueNm
  return 1;
}

}  // namespace

namespace internal {

bool TrySolve(const sim::MagneticModel& m, const MachineLimits& lim, double t, double we,
              OperatingPoint* op, const double* mtpa_id, RowLoci* row) {
  *op = OperatingPoint{};
  if (t == 0.0 && we <= 0) return true;
  const double s = t < 0 ? -1.0 : 1.0;
  const double id_min = -lim.i_max_a;
  if (row != nullptr && row->t != t) {
    row->t = t;
    row->points.clear();
    row->warm = false;
  }
  // (Each locus point's Newton starts cold, from the bracket: where the
  // torque is not monotone in iq (far beyond the measured region) a start
  // carried over from a neighbouring point can settle on another root.)
  // *f: the flux there (m.Flux(id, *iq)), for the voltage.
  auto iq_of = [&](double id, double* iq, sim::FluxLinkage* f) {
    const bool kept = row != nullptr && (id == id_min || (mtpa_id != nullptr && id == *mtpa_id));
    if (kept) {
      for (const auto& p : row->points) {
        if (p.id == id) {
          *iq = p.iq;
          *f = p.f;
          return p.ok;
        }
      }
    }
    const bool ok = SolveIqForTorque(m, lim, id, t, s, iq, 0.0, f);
    if (kept) row->points.push_back({id, ok, ok ? *iq : 0.0, ok ? *f : sim::FluxLinkage{}});
    return ok;
  };
  auto cur2 = [&](double id) {
    double iq;
    sim::FluxLinkage f;
    if (!iq_of(id, &iq, &f)) return 1e30;
    return id * id + iq * iq;
  };
  // Unconstrained least current (MTPA) along the constant-torque locus.
  double id = t == 0.0 ? 0.0 : (mtpa_id ? *mtpa_id : MinimiseScalar(cur2, id_min, 0.0));
  double iq = 0.0;
  sim::FluxLinkage f_id;
  if (t != 0.0 && !iq_of(id, &iq, &f_id)) return false;
  if (t == 0.0) f_id = m.Flux(0.0, 0.0, lim.temperature_c);
  // |u| at a locus point (d, q) from its flux f (VoltageV's value).
  auto volt = [&](double d, double q, const sim::FluxLinkage& f) {
    return we > 0 ? VoltageFromFlux(lim, d, q, we, f) : 0.0;
  };
  const double u_max = lim.UMaxV();
  if (we > 0 && volt(id, iq, f_id) > u_max) {
    // The fast solve first (FwNewton), from the row's last voltage-limited
    // cell, else from the MTPA point; away from the limit torque only.
    if (row != nullptr && row->fast && std::abs(t) < row->fast_below) {
      int verdict = FastFieldWeakening(m, lim, t, we, s, id, iq, row, op);
      if (verdict >= 0) return verdict == 1;
    }
    // Field weakening. Along the constant-torque locus the current grows
    // away from the MTPA point and the voltage has one minimum (the locus'
    // MTPV point) at a more negative id; the least-current feasible point is
    // where the voltage falls to u_max between the two.
    auto volt_on_locus = [&](double d) {
      double q;
      sim::FluxLinkage f;
      return iq_of(d, &q, &f) ? volt(d, q, f) : 1e30;
    };
    double lo = id_min;
    if (volt_on_locus(lo) > u_max) {
      lo = MinimiseScalar(volt_on_locus, id_min, id);
      if (volt_on_locus(lo) > u_max) return false;   // beyond the MTPV limit
    }
    // Root of g(id) = |u(id, iq(id))| - u_max on [lo feasible, hi = MTPA]
    // by regula falsi with the Illinois modification (Dowell & Jarratt,
    // BIT 11, 1971): superlinear, the bracket is kept, and the answer is its
    // feasible end. Each iq(id) starts from the roots at the bracket's ends.
    double hi = id, q_lo;
    sim::FluxLinkage f_lo;
    if (!iq_of(lo, &q_lo, &f_lo)) return false;
    double q_hi = iq;
    double g_lo = volt(lo, q_lo, f_lo) - u_max, g_hi = volt(hi, q_hi, f_id) - u_max;
    int side = 0;
    for (int k = 0; k < 100 && hi - lo > 2e-9 && g_lo < -1e-12 * u_max; ++k) {
      double x = hi - g_hi * (hi - lo) / (g_hi - g_lo);
      if (!(x > lo && x < hi)) x = 0.5 * (lo + hi);
      double q;
      sim::FluxLinkage f;
      const double guess = std::abs(q_lo + (q_hi - q_lo) * (x - lo) / (hi - lo));
      if (!SolveIqForTorque(m, lim, x, t, s, &q, guess, &f)) { hi = x; g_hi = 1.0; side = 0; continue; }
      const double g = volt(x, q, f) - u_max;
      if (g <= 0) {
        lo = x; g_lo = g; q_lo = q; f_lo = f;
        if (side == -1) g_hi *= 0.5;
        side = -1;
      } else {
        hi = x; g_hi = g; q_hi = q;
        if (side == 1) g_lo *= 0.5;
        side = 1;
      }
    }
    id = lo;
    iq = q_lo;
    f_id = f_lo;
    if (row != nullptr) {
      row->warm = true;
      row->warm_id = id;
      row->warm_iq = iq;
    }
  }
  if (std::hypot(id, iq) > lim.i_max_a * (1 + 1e-9)) return false;
  op->id_a = id;
  op->iq_a = iq;
  // TorqueNm's value, from the flux at (id, iq) already evaluated.
  op->torque_nm = physics::ElectromagneticTorque(lim.pole_pairs, f_id.psi_d_wb, f_id.psi_q_wb, id, iq);
  return true;
}

OperatingPoint SolveWithMax(const sim::MagneticModel& m, const MachineLimits& lim, double t,
                            double we, double tmax, const double* mtpa_id,
                            std::optional<OperatingPoint>* clamp, RowLoci* row, const LimitTorque* limit) {
  OperatingPoint op;
  // The fast field-weakening solve stays 1e-6 below the limit torque: there
  // the feasible arc of the locus shrinks to a point and the robust solve
  // decides feasibility.
  if (row != nullptr) row->fast_below = tmax * (1 - 1e-6);
  if (std::abs(t) <= tmax && TrySolve(m, lim, t, we, &op, mtpa_id, row)) return op;
  if (clamp != nullptr && clamp->has_value()) return **clamp;
  // Infeasible: deliver the largest torque of the same sign within limits.
  const double s = t < 0 ? -1.0 : 1.0;
  double tt = s * tmax;
  // The clamped point: the least-current point of the limit torque. Where
  // the limit torque's point is a corner of the limits (on the current
  // circle and the voltage limit), the voltage limit crosses the torque's
  // locus there (well-conditioned) and FwNewton from the limit's point
  // finds the clamped point next to it (checks as for a cell); the robust
  // solve's first step, the MTPA point of this torque (~60 locus solves),
  // is not needed: the checks place the root on its field-weakening side.
  // Elsewhere the limit is the locus' MTPV point, where the voltage limit
  // touches the locus: the root is ill-conditioned (1e-9 in torque moves it
  // by ~1e-6), and the robust solve's answer is kept.
  if (row != nullptr && row->fast && limit != nullptr && limit->direct && we > 0 &&
      std::hypot(limit->id, limit->iq) >= lim.i_max_a * (1 - 1e-6)) {
    double id, iq;
    sim::FluxLinkage f;
    if (FwNewton(m, lim, tt, we, s, limit->id, limit->iq, 0.0, &id, &iq, &f)) {
      const double r = std::hypot(id, iq) - lim.i_max_a * (1 + 1e-9);
      if (r < 0 && CurrentLimitSettled(r)) {
        op.id_a = id;
        op.iq_a = iq;
        op.torque_nm = physics::ElectromagneticTorque(lim.pole_pairs, f.psi_d_wb, f.psi_q_wb, id, iq);   // TorqueNm
        op.clamped = true;
        if (clamp != nullptr) *clamp = op;
        return op;
      }
    }
  }
  for (int k = 0; k < 8 && !TrySolve(m, lim, tt, we, &op); ++k) tt *= 1 - 1e-6 * (1 << (2 * k));
  op.clamped = true;
  if (clamp != nullptr) *clamp = op;
  return op;
}

}  // namespace internal

OperatingPoint SolveLeastCurrent(const sim::MagneticModel& m, const MachineLimits& lim, double t,
                                 double we) {
  OperatingPoint op;
  if (TrySolve(m, lim, t, we, &op)) return op;
  return SolveWithMax(m, lim, t, we, MaxTorqueNm(m, lim, we, t < 0 ? -1.0 : 1.0));
}

namespace {

// h at one locus point: the locus solve from its cold start at id, or from
// `iq_guess` (> 0, magnitude) when given (with its bracket grown lazily:
// SolveIqForTorque); *iq_found (optional): the root's magnitude. The
// voltage from the flux the locus solve ends with (no second evaluation).
double LocusPointH(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s, double t, double id,
                   double iq_guess = 0.0, double* iq_found = nullptr) {
  double iq;
  sim::FluxLinkage f;
  if (!SolveIqForTorque(m, lim, id, t, s, &iq, iq_guess, &f, iq_guess > 0)) return 1e30;
  if (iq_found != nullptr) *iq_found = std::abs(iq);
  const double c = std::hypot(id, iq) / lim.i_max_a;
  return we > 0 ? std::max(c, internal::VoltageFromFlux(lim, id, iq, we, f) / lim.UMaxV()) : c;
}

// h^2 at one locus point, from the locus solve started at `iq_guess` (> 0,
// magnitude; its bracket grown lazily) or cold: max(|i|^2 / i_max^2,
// |u|^2 / u_max^2), the square of LocusPointH's h without its two square
// roots (h^2 <= 1 where h <= 1, and a search comparing h^2 compares h).
double LocusPointH2(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s, double t, double id,
                    double iq_guess, double* iq_found, double* slope) {
  double iq;
  sim::FluxLinkage f;
  if (!SolveIqForTorque(m, lim, id, t, s, &iq, iq_guess, &f, iq_guess > 0, slope)) return 1e30;
  *iq_found = std::abs(iq);
  const double c2 = (id * id + iq * iq) / (lim.i_max_a * lim.i_max_a);
  if (!(we > 0) || !lim.rs_ohm) return c2;   // (as LocusPointH: no voltage without Rs)
  const double rs = *lim.rs_ohm, u_max = lim.UMaxV();
  const double ud = rs * id - we * f.psi_q_wb, uq = rs * iq + we * f.psi_d_wb;
  return std::max(c2, (ud * ud + uq * uq) / (u_max * u_max));
}

// Whether torque request s t (t > 0) can be met within both limits: some
// point of its constant-torque locus lies inside them, i.e. the minimum
// over the locus of h = max(|i| / i_max, |u| / u_max) is at most 1. |i|
// and |u| each have a single minimum along the locus (MTPA, MTPV), so h is
// quasi-convex and the scan + golden section finds its minimum even when
// the feasible arc is short (near the limit torque at high speed).
// A locus point found inside both limits settles it: the search stops there
// (a feasible request needs no more), so only an infeasible one costs the
// whole search.
// `warm`: each locus solve starts from the root at the last point searched
// (the golden section's points lie close together) instead of cold. Only
// where the torque is monotone in iq (within the measured region), so that
// the root is the same: beyond it a carried-over start can settle on
// another root. (Any root is a point of the locus, so a point it finds
// inside both limits proves feasibility either way.)
bool LocusFeasible(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s, double t,
                   bool warm = false) {
  bool found = false;
  // Warm: the last root (id_last, q_last: |iq|) and the locus' slope there
  // (d iq / d id), whose tangent gives the next start; the search runs on
  // h^2 (LocusPointH2).
  double id_last = 0.0, q_last = 0.0, slope = 0.0;
  auto h = [&](double id) {
    if (found) return 0.0;
    double v;
    if (warm) {
      const double guess = q_last > 0 ? q_last + s * slope * (id - id_last) : 0.0;
      double q = 0.0;
      v = LocusPointH2(m, lim, we, s, t, id, guess > 0 && std::isfinite(guess) ? guess : q_last, &q, &slope);
      if (v < 1e30) {
        id_last = id;
        q_last = q;
      }
    } else {
      v = LocusPointH(m, lim, we, s, t, id);
    }
    found = v <= 1.0;
    return v;
  };
  const double id = MinimiseScalar(h, -lim.i_max_a, 0.0, 24, 40);
  return found || h(id) <= 1.0;
}

// The limit torque by bisection on the request with LocusFeasible: robust,
// ~30 x 67 locus points. The fallback of MaxTorqueNm.
double MaxTorqueByBisection(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s) {
  double lo = 0.0, hi = 1.0;
  while (LocusFeasible(m, lim, we, s, hi) && hi < 1e5) { lo = hi; hi *= 2; }
  // 26 halvings: the limit torque to ~1e-8 of its value.
  for (int k = 0; k < 26; ++k) {
    const double mid = 0.5 * (lo + hi);
    if (LocusFeasible(m, lim, we, s, mid)) lo = mid; else hi = mid;
  }
  return lo;
}

// The limit torque as the largest s T over the feasible set {id in
// [-i_max, 0], s iq >= 0, |i| <= i_max, |u| <= u_max}. At fixed id the
// torque grows with |iq| (the locus solver's premise), so the best point of
// a column is its largest feasible |iq|: on the current circle, or below it
// the largest root of |u| = u_max. The limit torque is the maximum over id
// of that column torque: one 1-D maximisation (coarse scan + golden
// section) with a 1-D Newton root per column, warm-started from the last
// column's. A column with no feasible point scores minus its least
// (|u|^2 - u_max^2) / u_max^2, so the scan climbs towards the feasible
// columns even when they are a narrow band (high speed).
LimitTorque MaxTorqueDirect(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s) {
  const double u_max = lim.UMaxV();
  const bool voltage = we > 0 && lim.rs_ohm.has_value() && std::isfinite(u_max);
  const double rs = voltage ? *lim.rs_ohm : 0.0;
  double q_warm = -1.0;
  double q_last = 0.0;   // the last column's |iq| (its point, with the torque)
  // phi(q) = |u(id, s q)|^2 - u_max^2 and its slope in q.
  auto phi = [&](double id, double q, double* slope) {
    sim::FluxLinkage F;
    sim::DifferentialInductance L;
    m.FluxAndInductance(id, s * q, lim.temperature_c, &F, &L);
    const double ud = rs * id - we * F.psi_q_wb, uq = rs * s * q + we * F.psi_d_wb;
    // d psi_q / d iq = Lqq, d psi_d / d iq = Ldq, d iq / d q = s.
    *slope = 2 * (ud * (-we * s * L.lqq_h) + uq * s * (rs + we * L.ldq_h));
    return ud * ud + uq * uq - u_max * u_max;
  };
  auto column = [&](double id) {
    const double qc = std::sqrt(std::max(0.0, lim.i_max_a * lim.i_max_a - id * id));
    double q = qc;
    if (voltage) {
      double dc, d0;
      const double pc = phi(id, qc, &dc);
      if (pc > 0) {
        // Bracket [lo feasible, hi infeasible] of the largest root below qc.
        double lo = 0.0, hi = qc;
        if (phi(id, 0.0, &d0) > 0) {
          // |u| too large at both ends: a feasible |iq|, if any, lies
          // around the minimum of |u| along the column.
          const double qm = MinimiseScalar([&](double x) { double d; return phi(id, x, &d); }, 0.0, qc, 4, 25);
          double dm;
          const double pm = phi(id, qm, &dm);
          if (pm > 0) {
            q_last = qm;
            return -pm / (u_max * u_max);
          }
          lo = qm;
        }
        double x = q_warm > lo && q_warm < hi ? q_warm : hi, dx = dc;
        double fx = x == hi ? pc : phi(id, x, &dx);
        for (int it = 0; it < 60 && hi - lo > 1e-13 * lim.i_max_a; ++it) {
          if (fx > 0) hi = x; else lo = x;
          if (std::abs(fx) < 1e-13 * u_max * u_max) break;
          double next = dx != 0.0 ? x - fx / dx : 0.5 * (lo + hi);
          if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
          x = next;
          fx = phi(id, x, &dx);
        }
        // The root (Newton from the infeasible end converges from above, so
        // lo may still be the bracket's start), else the feasible side.
        q = fx <= 0 || std::abs(fx) < 1e-13 * u_max * u_max ? x : lo;
        q_warm = q;
      }
    }
    q_last = q;
    return s * TorqueNm(m, lim.pole_pairs, id, s * q, lim.temperature_c);
  };
  const double id = MinimiseScalar([&](double d) { return -column(d); }, -lim.i_max_a, 0.0, 24, 40);
  LimitTorque r;
  r.t = column(id);
  r.direct = true;
  r.id = id;
  r.iq = s * q_last;
  return r;
}

}  // namespace

namespace {

// The check of a limit torque d->t found at d->id (MaxTorqueDirect or
// CornerLimit): a request 1e-7 below is feasible and 1e-7 above is not
// (LocusFeasible, the bisection's test). If it passes, d->t becomes the
// limit just inside: 1e-9 below (below what the golden section resolves),
// so that the least-current solver at this torque finds a feasible point;
// the bisection ended ~1e-8 inside.
// The request below is shown feasible by one locus point when it can be:
// the point of its locus at the maximum's id is inside both limits there
// (its |iq| is below the maximum's, where the column is feasible), and one
// point inside both limits is what LocusFeasible's search looks for.
bool PassesLimitCheck(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s, LimitTorque* d,
                      bool warm = false) {
  constexpr double kCheck = 1e-7;
  const double t = d->t;
  if (t > 0 && std::isfinite(t) &&
      (LocusPointH(m, lim, we, s, t * (1 - kCheck), d->id) <= 1.0 || LocusFeasible(m, lim, we, s, t * (1 - kCheck))) &&
      !LocusFeasible(m, lim, we, s, t * (1 + kCheck), warm)) {
    d->t = t * (1 - 1e-9);
    return true;
  }
  return false;
}

// The limit torque where it lies at a corner of the limits: the point on
// both the current circle and the voltage limit (between base speed and
// the speed from which the locus' MTPV point limits instead), by a 2-D
// Newton on (|i|^2 = i_max^2, |u|^2 = u_max^2) from the corner at the
// previous speed (~4 surface evaluations, against MaxTorqueDirect's ~67
// columns). It is a maximum of the torque over the feasible set where the
// torque's gradient is a positive combination of the two limits' outward
// gradients (KKT multipliers both > 0: with two independent active limits
// in the plane no feasible direction is left, a strict local maximum).
// Whether it is the largest, PassesLimitCheck decides (its search above
// the limit covers the whole locus); otherwise false.
bool CornerLimit(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s, double id0,
                 double iq0, LimitTorque* out) {
  const double u_max = lim.UMaxV(), u2 = u_max * u_max, i2 = lim.i_max_a * lim.i_max_a;
  const double rs = *lim.rs_ohm;
  double id = id0, iq = iq0;
  for (int it = 0; it < 16; ++it) {
    sim::FluxLinkage F;
    sim::DifferentialInductance L;
    m.FluxAndInductance(id, iq, lim.temperature_c, &F, &L);
    const double ud = rs * id - we * F.psi_q_wb, uq = rs * iq + we * F.psi_d_wb;
    const double c1 = id * id + iq * iq - i2, c2 = ud * ud + uq * uq - u2;
    // Gradients of |u|^2 (as in FwNewton) and of |i|^2 = (2 id, 2 iq).
    const double g_d = 2 * (ud * (rs - we * L.ldq_h) + uq * we * L.ldd_h);
    const double g_q = 2 * (-ud * we * L.lqq_h + uq * (rs + we * L.ldq_h));
    const double det = 2 * id * g_q - 2 * iq * g_d;
    if (!(std::abs(det) > 0) || !std::isfinite(det)) return false;
    if (std::abs(c1) <= 1e-13 * i2 && std::abs(c2) <= 1e-13 * u2) {
      const double t_d = 1.5 * lim.pole_pairs * (L.ldd_h * iq - F.psi_q_wb - L.ldq_h * id);
      const double t_q = physics::TorqueSlopeIq(lim.pole_pairs, F.psi_d_wb, L.ldq_h, L.lqq_h, id, iq);
      // s grad T = l1 grad|i|^2 + l2 grad|u|^2, by Cramer's rule.
      const double l1 = s * (t_d * g_q - t_q * g_d) / det, l2 = s * (2 * id * t_q - 2 * iq * t_d) / det;
      if (!(s * iq > 0 && id >= -lim.i_max_a && id <= 0 && l1 > 0 && l2 > 0)) return false;
      out->t = s * physics::ElectromagneticTorque(lim.pole_pairs, F.psi_d_wb, F.psi_q_wb, id, iq);
      out->direct = true;
      out->id = id;
      out->iq = iq;
      return true;
    }
    if (!internal::DampedNewtonStep(2 * id, 2 * iq, g_d, g_q, c1, c2, 0.25 * lim.i_max_a, &id, &iq)) return false;
  }
  return false;
}

// MaxTorqueNm with its point: MaxTorqueDirect, checked.
// `warm`: the check's search above the limit warm-starts its locus solves
// (PassesLimitCheck; within the measured current limit only).
LimitTorque CheckedLimitTorque(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s,
                               bool warm = false) {
  // The limit torque is the largest request some point of whose locus lies
  // inside both limits. It was found by bisection on the request
  // (MaxTorqueByBisection: ~30 x 67 locus points, each a Newton solve),
  // which dominated the tables' time. Now it is computed directly as the
  // largest torque of the feasible set (MaxTorqueDirect, ~67 columns) and
  // then checked by the bisection's own test on both sides: a request
  // 1e-7 below must be feasible and 1e-7 above must not. Where the check
  // fails (a feasible set the column search does not resolve), the
  // bisection decides, as before.
  // The request below is shown feasible by one locus point when it can be:
  // the point of its locus at the maximum's id is inside both limits there
  // (its |iq| is below the maximum's, where the column is feasible), and
  // one point inside both limits is what LocusFeasible's search looks for.
  LimitTorque d = MaxTorqueDirect(m, lim, we, s);
  if (PassesLimitCheck(m, lim, we, s, &d, warm)) return d;
  LimitTorque b;
  b.t = MaxTorqueByBisection(m, lim, we, s);
  return b;
}

}  // namespace

double MaxTorqueNm(const sim::MagneticModel& m, const MachineLimits& lim, double we,
                   double sign) {
  return CheckedLimitTorque(m, lim, we, sign < 0 ? -1.0 : 1.0).t;
}

namespace internal {

LimitTorque LimitTorqueAt(const sim::MagneticModel& m, const MachineLimits& lim, double we, double sign) {
  return CheckedLimitTorque(m, lim, we, sign < 0 ? -1.0 : 1.0);
}

}  // namespace internal

namespace internal {

std::vector<LimitTorque> LimitTorques(const sim::MagneticModel& m, const MachineLimits& lim,
                                      const std::vector<double>& we, double sign, bool fast,
                                      const LimitTorque* standstill) {
  const double s = sign < 0 ? -1.0 : 1.0;
  // At standstill only the current limit binds. The feasible set at a speed
  // (inside the current circle and the voltage limit) is part of the one at
  // standstill, so its largest torque is at most the standstill one; where
  // the standstill maximum's point also meets this speed's voltage limit,
  // it is in the set and the limit torque is the standstill one (below base
  // speed: one voltage evaluation instead of a maximisation and its checks).
  const LimitTorque still = standstill != nullptr ? *standstill : CheckedLimitTorque(m, lim, 0.0, s, fast);
  const double u_max = lim.UMaxV();
  std::vector<LimitTorque> out;
  out.reserve(we.size());
  // Above base speed, a limit at a corner of the limits starts the next
  // speed's CornerLimit (the corner moves little from speed to speed), an
  // MTPV-type one (inside the current limit) the next speed's MtpvLimit.
  const LimitTorque* corner = still.direct ? &still : nullptr;
  const LimitTorque* mtpv = nullptr;
  for (double w : we) {
    if (w <= 0 || (still.direct && lim.HasVoltageLimit() && VoltageV(m, lim, still.id, still.iq, w) <= u_max)) {
      out.push_back(still);
      continue;
    }
    LimitTorque c;
    if (fast && corner != nullptr && lim.HasVoltageLimit() && CornerLimit(m, lim, w, s, corner->id, corner->iq, &c) &&
        PassesLimitCheck(m, lim, w, s, &c, true)) {
      out.push_back(c);
    } else if (fast && mtpv != nullptr && lim.HasVoltageLimit() && MtpvLimit(m, lim, w, s, mtpv->id, mtpv->iq, &c) &&
               PassesLimitCheck(m, lim, w, s, &c, true)) {
      out.push_back(c);
    } else {
      out.push_back(CheckedLimitTorque(m, lim, w, s, fast));
    }
    const LimitTorque& l = out.back();
    const bool at_current_limit = std::hypot(l.id, l.iq) >= lim.i_max_a * (1 - 1e-6);
    corner = l.direct && at_current_limit ? &l : nullptr;
    mtpv = l.direct && !at_current_limit ? &l : nullptr;
  }
  return out;
}

}  // namespace internal

}  // namespace fluxcal::tables
