#include "tables/tables.h"

#include <zlib.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <limits>
#include <numbers>
#include <optional>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "nlohmann/json.hpp"
#include "fitting/calibration.h"
#include "io/sha256.h"
#include "plot/plot.h"
#include "tables/a2l.h"
#include "physics/speed.h"
#include "physics/torque.h"

namespace fluxcal::tables {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kGolden = 0.61803398874989484820;

// iq (sign s) on the constant-torque locus through id: T(id, iq) = t.
// Newton with a bisection safeguard; dT/diq = 1.5 p (psi_d + Ldq iq - Lqq id).
// `iq_guess_a` (> 0, magnitude): a start close to the root, e.g. the root at
// a neighbouring id; otherwise the start scales linearly from the bracket.
bool SolveIqForTorque(const sim::MagneticModel& m, const MachineLimits& lim, double id, double t,
                      double s, double* iq_out, double iq_guess_a = 0.0) {
  const double target = std::abs(t);
  double lo = 0.0, hi = std::max(10.0, lim.i_max_a);
  auto torque = [&](double iq) { return s * TorqueNm(m, lim.pole_pairs, id, s * iq, lim.temperature_c); };
  int grow = 0;
  double t_hi;
  while ((t_hi = torque(hi)) < target) {
    hi *= 2;
    if (++grow > 8) return false;
  }
  double iq = iq_guess_a > lo && iq_guess_a < hi
                  ? iq_guess_a
                  : std::clamp(target / std::max(1e-9, t_hi) * hi, lo, hi);
  for (int it = 0; it < 60; ++it) {
    // One surface evaluation per iteration serves both T and dT/diq (a
    // spline calibration shares the basis between flux and inductance).
    sim::FluxLinkage F;
    sim::DifferentialInductance L;
    m.FluxAndInductance(id, s * iq, lim.temperature_c, &F, &L);
    const double f = s * physics::ElectromagneticTorque(lim.pole_pairs, F.psi_d_wb, F.psi_q_wb, id, s * iq) - target;
    if (std::abs(f) < 1e-10 * (1.0 + target)) break;
    if (f > 0) hi = iq; else lo = iq;
    const double d = physics::TorqueSlopeIq(lim.pole_pairs, F.psi_d_wb, L.ldq_h, L.lqq_h, id, s * iq);
    double next = iq - f / (d > 1e-12 ? d : 1e-12);
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    if (hi - lo < 1e-12) break;
    iq = next;
  }
  *iq_out = s * iq;
  return true;
}

// Minimises f on [a, b]: coarse scan, then golden section around the best.
template <typename F>
double MinimiseScalar(F f, double a, double b, int scan = 16, int iters = 40) {
  double best = a, fbest = f(a);
  for (int k = 1; k <= scan; ++k) {
    const double x = a + (b - a) * k / scan;
    const double fx = f(x);
    if (fx < fbest) { fbest = fx; best = x; }
  }
  double lo = std::max(a, best - (b - a) / scan), hi = std::min(b, best + (b - a) / scan);
  double x1 = hi - kGolden * (hi - lo), x2 = lo + kGolden * (hi - lo);
  double f1 = f(x1), f2 = f(x2);
  for (int k = 0; k < iters; ++k) {
    if (f1 < f2) { hi = x2; x2 = x1; f2 = f1; x1 = hi - kGolden * (hi - lo); f1 = f(x1); }
    else { lo = x1; x1 = x2; f1 = f2; x2 = lo + kGolden * (hi - lo); f2 = f(x2); }
  }
  return 0.5 * (lo + hi);
}

std::string NowUtc() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
}

std::vector<double> Linspace(double a, double b, int n) {
  std::vector<double> v(n);
  for (int k = 0; k < n; ++k) v[k] = n == 1 ? a : a + (b - a) * k / (n - 1);
  return v;
}

}  // namespace

double MachineLimits::UMaxV() const {
  return udc_v ? modulation_limit * *udc_v / std::sqrt(3.0) : std::numeric_limits<double>::quiet_NaN();
}

double TorqueNm(const sim::MagneticModel& m, int pp, double id, double iq, double temperature_c) {
  const auto f = m.Flux(id, iq, temperature_c);
  return physics::ElectromagneticTorque(pp, f.psi_d_wb, f.psi_q_wb, id, iq);
}

double VoltageV(const sim::MagneticModel& m, const MachineLimits& lim, double id, double iq, double we) {
  if (!lim.rs_ohm) return std::numeric_limits<double>::quiet_NaN();
  const double rs = *lim.rs_ohm;
  const auto f = m.Flux(id, iq, lim.temperature_c);
  return std::hypot(rs * id - we * f.psi_q_wb, rs * iq + we * f.psi_d_wb);
}

namespace {

// The locus points of one torque request that every speed of a
// field-weakening row asks for again: its MTPA point and its end at
// -i_max. A locus point depends on the request and id only (the solve is
// deterministic), so the row keeps them; TrySolve looks them up by exact id.
struct RowLoci {
  double t = std::numeric_limits<double>::quiet_NaN();
  struct Point { double id; bool ok; double iq; };
  std::vector<Point> points;
};

// Least-current point for torque t under the limits; false if infeasible.
// `mtpa_id` (optional): the least-current id of this torque without a
// voltage limit, when already known (it does not depend on speed).
// `row` (optional): the kept locus points of this request (RowLoci).
bool TrySolve(const sim::MagneticModel& m, const MachineLimits& lim, double t, double we,
              OperatingPoint* op, const double* mtpa_id = nullptr, RowLoci* row = nullptr) {
  *op = OperatingPoint{};
  if (t == 0.0 && we <= 0) return true;
  const double s = t < 0 ? -1.0 : 1.0;
  const double id_min = -lim.i_max_a;
  if (row != nullptr && row->t != t) *row = RowLoci{t, {}};
  // (Each locus point's Newton starts cold, from the bracket: where the
  // torque is not monotone in iq (far beyond the measured region) a start
  // carried over from a neighbouring point can settle on another root.)
  auto iq_of = [&](double id, double* iq) {
    const bool kept = row != nullptr && (id == id_min || (mtpa_id != nullptr && id == *mtpa_id));
    if (kept) {
      for (const auto& p : row->points) {
        if (p.id == id) {
          *iq = p.iq;
          return p.ok;
        }
      }
    }
    const bool ok = SolveIqForTorque(m, lim, id, t, s, iq);
    if (kept) row->points.push_back({id, ok, ok ? *iq : 0.0});
    return ok;
  };
  auto cur2 = [&](double id) {
    double iq;
    if (!iq_of(id, &iq)) return 1e30;
    return id * id + iq * iq;
  };
  // Unconstrained least current (MTPA) along the constant-torque locus.
  double id = t == 0.0 ? 0.0 : (mtpa_id ? *mtpa_id : MinimiseScalar(cur2, id_min, 0.0));
  double iq = 0.0;
  if (t != 0.0 && !iq_of(id, &iq)) return false;
  auto volt = [&](double d, double q) { return we > 0 ? VoltageV(m, lim, d, q, we) : 0.0; };
  const double u_max = lim.UMaxV();
  if (we > 0 && volt(id, iq) > u_max) {
    // Field weakening. Along the constant-torque locus the current grows
    // away from the MTPA point and the voltage has one minimum (the locus'
    // MTPV point) at a more negative id; the least-current feasible point is
    // where the voltage falls to u_max between the two.
    auto volt_on_locus = [&](double d) {
      double q;
      return iq_of(d, &q) ? volt(d, q) : 1e30;
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
    if (!iq_of(lo, &q_lo)) return false;
    double q_hi = iq;
    double g_lo = volt(lo, q_lo) - u_max, g_hi = volt(hi, q_hi) - u_max;
    int side = 0;
    for (int k = 0; k < 100 && hi - lo > 2e-9 && g_lo < -1e-12 * u_max; ++k) {
      double x = hi - g_hi * (hi - lo) / (g_hi - g_lo);
      if (!(x > lo && x < hi)) x = 0.5 * (lo + hi);
      double q;
      const double guess = std::abs(q_lo + (q_hi - q_lo) * (x - lo) / (hi - lo));
      if (!SolveIqForTorque(m, lim, x, t, s, &q, guess)) { hi = x; g_hi = 1.0; side = 0; continue; }
      const double g = volt(x, q) - u_max;
      if (g <= 0) {
        lo = x; g_lo = g; q_lo = q;
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
  }
  if (std::hypot(id, iq) > lim.i_max_a * (1 + 1e-9)) return false;
  op->id_a = id;
  op->iq_a = iq;
  op->torque_nm = TorqueNm(m, lim.pole_pairs, id, iq, lim.temperature_c);
  return true;
}

// As SolveLeastCurrent, with the limit torque at this speed already known.
// `clamp` (optional): the clamped point of this speed and torque sign, once
// computed; it depends on nothing else, so a field-weakening column
// computes it once for all the requests beyond its limit torque.
OperatingPoint SolveWithMax(const sim::MagneticModel& m, const MachineLimits& lim, double t,
                            double we, double tmax, const double* mtpa_id = nullptr,
                            std::optional<OperatingPoint>* clamp = nullptr, RowLoci* row = nullptr) {
  OperatingPoint op;
  if (std::abs(t) <= tmax && TrySolve(m, lim, t, we, &op, mtpa_id, row)) return op;
  if (clamp != nullptr && clamp->has_value()) return **clamp;
  // Infeasible: deliver the largest torque of the same sign within limits.
  const double s = t < 0 ? -1.0 : 1.0;
  double tt = s * tmax;
  for (int k = 0; k < 8 && !TrySolve(m, lim, tt, we, &op); ++k) tt *= 1 - 1e-6 * (1 << (2 * k));
  op.clamped = true;
  if (clamp != nullptr) *clamp = op;
  return op;
}

}  // namespace

OperatingPoint SolveLeastCurrent(const sim::MagneticModel& m, const MachineLimits& lim, double t,
                                 double we) {
  OperatingPoint op;
  if (TrySolve(m, lim, t, we, &op)) return op;
  return SolveWithMax(m, lim, t, we, MaxTorqueNm(m, lim, we, t < 0 ? -1.0 : 1.0));
}

namespace {

// Whether torque request s t (t > 0) can be met within both limits: some
// point of its constant-torque locus lies inside them, i.e. the minimum
// over the locus of h = max(|i| / i_max, |u| / u_max) is at most 1. |i|
// and |u| each have a single minimum along the locus (MTPA, MTPV), so h is
// quasi-convex and the scan + golden section finds its minimum even when
// the feasible arc is short (near the limit torque at high speed).
// A locus point found inside both limits settles it: the search stops there
// (a feasible request needs no more), so only an infeasible one costs the
// whole search.
bool LocusFeasible(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s, double t) {
  bool found = false;
  auto h = [&](double id) {
    if (found) return 0.0;
    double iq;
    if (!SolveIqForTorque(m, lim, id, t, s, &iq)) return 1e30;
    const double c = std::hypot(id, iq) / lim.i_max_a;
    const double v = we > 0 ? std::max(c, VoltageV(m, lim, id, iq, we) / lim.UMaxV()) : c;
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
double MaxTorqueDirect(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s) {
  const double u_max = lim.UMaxV();
  const bool voltage = we > 0 && lim.rs_ohm.has_value() && std::isfinite(u_max);
  const double rs = voltage ? *lim.rs_ohm : 0.0;
  double q_warm = -1.0;
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
          if (pm > 0) return -pm / (u_max * u_max);
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
    return s * TorqueNm(m, lim.pole_pairs, id, s * q, lim.temperature_c);
  };
  const double id = MinimiseScalar([&](double d) { return -column(d); }, -lim.i_max_a, 0.0, 24, 40);
  return column(id);
}

}  // namespace

double MaxTorqueNm(const sim::MagneticModel& m, const MachineLimits& lim, double we,
                   double sign) {
  const double s = sign < 0 ? -1.0 : 1.0;
  // The limit torque is the largest request some point of whose locus lies
  // inside both limits. It was found by bisection on the request
  // (MaxTorqueByBisection: ~30 x 67 locus points, each a Newton solve),
  // which dominated the tables' time. Now it is computed directly as the
  // largest torque of the feasible set (MaxTorqueDirect, ~67 columns) and
  // then checked by the bisection's own test on both sides: a request
  // 1e-7 below must be feasible and 1e-7 above must not. Where the check
  // fails (a feasible set the column search does not resolve), the
  // bisection decides, as before.
  const double t = MaxTorqueDirect(m, lim, we, s);
  constexpr double kCheck = 1e-7;
  if (t > 0 && std::isfinite(t) && LocusFeasible(m, lim, we, s, t * (1 - kCheck)) &&
      !LocusFeasible(m, lim, we, s, t * (1 + kCheck))) {
    // Just inside the limit (1e-9 of it, below what the golden section
    // resolves), so that the least-current solver at this torque finds a
    // feasible point; the bisection ended ~1e-8 inside.
    return t * (1 - 1e-9);
  }
  return MaxTorqueByBisection(m, lim, we, s);
}

absl::StatusOr<std::vector<double>> RoundBreakpoints(double lo, double hi, int max_points, const std::string& flag) {
  if (!std::isfinite(lo) || !std::isfinite(hi) || !(hi > lo)) {
    return absl::InvalidArgumentError(absl::StrFormat("%s: no range to put breakpoints in ([%.6g, %.6g])", flag, lo, hi));
  }
  if (max_points < 2) return absl::InvalidArgumentError(absl::StrCat(flag, ": at least 2 breakpoints"));
  // Steps m 10^e, m in {1, 2, 5}, upwards from a tenth of the even spacing
  // (a step below (hi - lo) / (max_points - 1) never fits): the first whose
  // multiples in [lo, hi] number at most max_points. The multiples are
  // counted in integers; a range end within 1e-9 of its size of a multiple
  // counts as that multiple (6000 rpm is on the 200 rpm grid).
  const double eps = 1e-9;
  const double raw = (hi - lo) / (max_points - 1);
  int e = static_cast<int>(std::floor(std::log10(raw))) - 1;
  for (int tries = 0; tries < 12; ++tries, ++e) {
    for (int mant : {1, 2, 5}) {
      // 10^|e| is exact in a double up to 10^22; so is k m (|k m| < 2^53).
      double p10 = 1.0;
      for (int k = 0; k < std::abs(e); ++k) p10 *= 10.0;
      const double step = e >= 0 ? mant * p10 : mant / p10;
      const double span = (hi - lo) / step;
      const double k_lo = std::ceil(lo / step - eps * std::max(1.0, span));
      const double k_hi = std::floor(hi / step + eps * std::max(1.0, span));
      const double count = k_hi - k_lo + 1;
      if (count > max_points) continue;
      if (count < 2) {
        return absl::InvalidArgumentError(absl::StrFormat(
            "%s: %d breakpoints cannot hold round steps (1, 2, 5 x 10^k) over [%.6g, %.6g]; give more", flag,
            max_points, lo, hi));
      }
      std::vector<double> v;
      v.reserve(static_cast<size_t>(count));
      for (double k = k_lo; k <= k_hi; ++k) {
        const double km = k * mant;   // an integer, exact
        const double x = e >= 0 ? km * p10 : km / p10;
        v.push_back(x == 0 ? 0.0 : x);   // no -0 in a table
      }
      return v;
    }
  }
  return absl::InternalError(absl::StrCat(flag, ": no round step found"));
}

absl::StatusOr<Table> BuildTable(const sim::MagneticModel& m, const MachineLimits& lim,
                                 const TableSpec& spec) {
  if (spec.points < 2 || spec.points > 4096) {
    return absl::InvalidArgumentError(absl::StrCat("flag --points: must be 2..4096, got ", spec.points));
  }
  if (lim.pole_pairs < 1 || lim.pole_pairs > 100) {
    return absl::InvalidArgumentError(absl::StrCat(
        "limits: pole_pairs ", lim.pole_pairs == 0 ? std::string("unknown") : absl::StrCat(lim.pole_pairs),
        " (1..100 required: the calibration's)"));
  }
  if (!(lim.i_max_a > 0) || !std::isfinite(lim.i_max_a)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "limits: i_max_a %.6g A: a current limit must be given and positive (the calibration's measured limit or "
        "--i-max-a)", lim.i_max_a));
  }
  if ((lim.udc_v && !(*lim.udc_v > 0 && std::isfinite(*lim.udc_v))) ||
      (lim.rs_ohm && !(*lim.rs_ohm >= 0 && std::isfinite(*lim.rs_ohm)))) {
    return absl::InvalidArgumentError("limits: udc_v must be positive and rs_ohm non-negative when given");
  }
  if (spec.kind == "fw" && !lim.HasVoltageLimit()) {
    // u = Rs i + w J psi against m Udc / sqrt(3): neither may be assumed.
    return absl::InvalidArgumentError(absl::StrCat(
        "table fw: the field-weakening map needs the voltage limit: ",
        !lim.udc_v ? "the DC-link voltage udc_v (--udc-v)" : "", !lim.udc_v && !lim.rs_ohm ? " and " : "",
        !lim.rs_ohm ? "the stator resistance rs_ohm (--rs-ohm)" : "", " not known"));
  }
  const double meas = spec.measured_current_limit_a;
  if (meas > 0 && !spec.allow_extrapolation && lim.i_max_a > meas * (1 + 1e-9)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "flag --i-max-a: %.6g A exceeds the calibration's measured current limit %.6g A; the table would rest on "
        "extrapolated magnetics (--allow-extrapolation computes it anyway, cells flagged 'extrapolated')",
        lim.i_max_a, meas));
  }
  Table t;
  t.kind = spec.kind;
  t.serial = spec.serial;
  t.calibration_version = spec.calibration_version;
  t.model = spec.model;
  t.created_utc = NowUtc();
  t.fluxcal_version = FluxcalVersion();
  t.verdict = spec.verdict.empty() ? kVerdictUnknown : spec.verdict;
  t.release_state = spec.release_state.empty() ? kReleaseUnknown : spec.release_state;
  t.limits = lim;
  // The permanent-magnet flux linkage as the model gives it (psi_d at zero
  // current), whatever the model family's parameterisation.
  t.psi_pm_wb = m.Flux(0.0, 0.0, lim.temperature_c).psi_d_wb;
  t.speed_max_rpm = spec.kind == "fw" ? spec.speed_max_rpm : 0.0;
  t.measured_current_limit_a = meas > 0 ? meas : 0.0;
  t.allow_extrapolation = spec.allow_extrapolation;
  const double tmax = MaxTorqueNm(m, lim, 0.0);
  if (spec.kind == "mtpa") {
    auto axis = RoundBreakpoints(spec.include_generating ? -tmax : 0.0, tmax, spec.points);
    if (!axis.ok()) return axis.status();
    const auto& tq = *axis;
    Output id{"id_a", {}}, iq{"iq_a", {}};
    for (double x : tq) {
      const auto op = SolveWithMax(m, lim, x, 0.0, tmax);
      id.values.push_back(op.id_a);
      iq.values.push_back(op.iq_a);
      t.clamped.push_back(op.clamped);
    }
    t.axes = {{"torque_nm", tq}};
    t.outputs = {id, iq};
  } else if (spec.kind == "mtpv") {
    // Flux-magnitude axis from the smallest to the largest |psi| met inside
    // the current limit on the motoring half plane.
    double lmin = 1e9, lmax = 0;
    for (double a = 0; a <= kPi; a += kPi / 90) {
      const double id = -lim.i_max_a * std::sin(a * 0.5), iq = lim.i_max_a * std::cos(a * 0.5);
      const auto f = m.Flux(id, iq, lim.temperature_c);
      lmin = std::min(lmin, std::hypot(f.psi_d_wb, f.psi_q_wb));
      lmax = std::max(lmax, std::hypot(f.psi_d_wb, f.psi_q_wb));
    }
    lmin = std::max(lmin, 0.05 * lmax);
    // For each id, the iq >= 0 with |psi(id, iq)| = l (|psi| grows with
    // iq); maximise torque over id.
    struct MtpvPoint { double id = 0, iq = 0; bool ok = false; };
    auto solve = [&](double l) {
      auto iq_of = [&](double d, double* q) {
        double lo = 0, hi = 4 * lim.i_max_a;
        auto mag = [&](double x) {
          const auto f = m.Flux(d, x, lim.temperature_c);
          return std::hypot(f.psi_d_wb, f.psi_q_wb);
        };
        if (mag(lo) > l || mag(hi) < l) return false;
        for (int k = 0; k < 60; ++k) {
          const double mid = 0.5 * (lo + hi);
          (mag(mid) < l ? lo : hi) = mid;
        }
        *q = 0.5 * (lo + hi);
        return true;
      };
      auto neg_t = [&](double d) {
        double q;
        if (!iq_of(d, &q)) return 1e30;
        return -TorqueNm(m, lim.pole_pairs, d, q, lim.temperature_c);
      };
      MtpvPoint p;
      p.id = MinimiseScalar(neg_t, -2 * lim.i_max_a, 0.0);
      p.ok = iq_of(p.id, &p.iq);
      return p;
    };
    auto inside = [&](const MtpvPoint& p) { return p.ok && std::hypot(p.id, p.iq) <= lim.i_max_a * (1 + 1e-9); };
    if (!spec.allow_extrapolation) {
      // Restrict the flux axis to the fluxes whose MTPV point lies inside the
      // current limit (by default the measured one): beyond it the curve is
      // the model's extrapolation, not the measured machine. The longest run
      // of inside points on a 64-step scan, its ends refined by bisection.
      constexpr int kScan = 64;
      std::vector<bool> in(kScan + 1);
      const auto scan = Linspace(lmin, lmax, kScan + 1);
      for (int k = 0; k <= kScan; ++k) in[k] = inside(solve(scan[k]));
      int best_a = -1, best_b = -1;
      for (int k = 0; k <= kScan;) {
        if (!in[k]) { ++k; continue; }
        int e = k;
        while (e + 1 <= kScan && in[e + 1]) ++e;
        if (e - k > best_b - best_a) { best_a = k; best_b = e; }
        k = e + 1;
      }
      if (best_a < 0) {
        return absl::FailedPreconditionError(absl::StrFormat(
            "table mtpv: at every flux in [%.6g, %.6g] Wb the MTPV point lies beyond the current limit %.6g A, "
            "i.e. in extrapolated magnetics; --allow-extrapolation exports it anyway (cells flagged)",
            lmin, lmax, lim.i_max_a));
      }
      auto refine = [&](double good, double bad) {
        for (int k = 0; k < 24; ++k) {
          const double mid = 0.5 * (good + bad);
          (inside(solve(mid)) ? good : bad) = mid;
        }
        return good;
      };
      double a = scan[best_a], b = scan[best_b];
      if (best_a > 0) a = refine(a, scan[best_a - 1]);
      if (best_b < kScan) b = refine(b, scan[best_b + 1]);
      if (!(b > a)) {
        return absl::FailedPreconditionError(absl::StrFormat(
            "table mtpv: the MTPV curve touches the current limit %.6g A only at %.6g Wb; "
            "--allow-extrapolation exports the extrapolated curve (cells flagged)", lim.i_max_a, a));
      }
      lmin = a;
      lmax = b;
    }
    auto axis = RoundBreakpoints(lmin, lmax, spec.points);
    if (!axis.ok()) return axis.status();
    const auto& lam = *axis;
    Output id{"id_a", {}}, iq{"iq_a", {}}, tq{"torque_nm", {}};
    for (double l : lam) {
      const auto p = solve(l);
      id.values.push_back(p.id);
      iq.values.push_back(p.iq);
      tq.values.push_back(p.ok ? TorqueNm(m, lim.pole_pairs, p.id, p.iq, lim.temperature_c) : 0.0);
      t.clamped.push_back(!inside(p));
    }
    t.axes = {{"psi_wb", lam}};
    t.outputs = {id, iq, tq};
  } else if (spec.kind == "fw") {
    if (!(spec.speed_max_rpm > 0) || !std::isfinite(spec.speed_max_rpm)) {
      return absl::InvalidArgumentError("flag --speed-max-rpm: must be positive");
    }
    auto tq_axis = RoundBreakpoints(spec.include_generating ? -tmax : 0.0, tmax, spec.points);
    if (!tq_axis.ok()) return tq_axis.status();
    auto n_axis = RoundBreakpoints(0.0, spec.speed_max_rpm, spec.speed_points, "--speed-points");
    if (!n_axis.ok()) return n_axis.status();
    const auto& tq = *tq_axis;
    const auto& n = *n_axis;
    t.speed_max_rpm = n.back();   // the axis' top: the last round speed within the range
    Output id{"id_a", {}}, iq{"iq_a", {}};
    // Limit torque per speed, motoring and generating (they differ at speed:
    // the resistive drop subtracts from the voltage when generating).
    std::vector<double> tlim_motor(n.size()), tlim_gen(n.size());
    for (size_t j = 0; j < n.size(); ++j) {
      const double we = physics::RpmToElectricalRadS(n[j], lim.pole_pairs);
      tlim_motor[j] = MaxTorqueNm(m, lim, we, 1.0);
      tlim_gen[j] = spec.include_generating ? MaxTorqueNm(m, lim, we, -1.0) : 0.0;
    }
    // The clamped point per speed and torque sign (SolveWithMax).
    std::vector<std::optional<OperatingPoint>> clamp_motor(n.size()), clamp_gen(n.size());
    for (double x : tq) {
      // The MTPA point of this torque row is the same at every speed.
      OperatingPoint mtpa;
      const bool have_mtpa = TrySolve(m, lim, x, 0.0, &mtpa);
      RowLoci row;
      for (size_t j = 0; j < n.size(); ++j) {
        const double we = physics::RpmToElectricalRadS(n[j], lim.pole_pairs);
        const double tlim = x < 0 ? tlim_gen[j] : tlim_motor[j];
        const auto op = SolveWithMax(m, lim, x, we, tlim, have_mtpa ? &mtpa.id_a : nullptr,
                                     x < 0 ? &clamp_gen[j] : &clamp_motor[j], &row);
        id.values.push_back(op.id_a);
        iq.values.push_back(op.iq_a);
        t.clamped.push_back(op.clamped);
      }
    }
    t.axes = {{"torque_nm", tq}, {"speed_rpm", n}};
    t.outputs = {id, iq};
  } else {
    return absl::InvalidArgumentError(absl::StrCat("flag --table: expected mtpa, mtpv or fw, got '", spec.kind, "'"));
  }
  // Extrapolated: the operating point of the cell lies beyond the measured
  // current limit (the disc the identified points cover), or outside a
  // calibration's measured region and its mirror image. By symmetry: on
  // the mirror image only (a generating row of a motoring-only bench, from
  // a model symmetric in iq). Not positive definite: the model's
  // differential inductance there fails Sylvester's test (one test for the
  // fit, queries and tables: fit::NotPositiveDefiniteReason).
  const auto& idv = t.outputs[0].values;
  const auto& iqv = t.outputs[1].values;
  const auto* cal = dynamic_cast<const fit::Calibration*>(&m);
  t.extrapolated.assign(idv.size(), 0);
  t.by_symmetry.assign(idv.size(), 0);
  t.not_positive_definite.assign(idv.size(), 0);
  for (size_t k = 0; k < idv.size(); ++k) {
    if (meas > 0) t.extrapolated[k] = std::hypot(idv[k], iqv[k]) > meas * (1 + 1e-9);
    if (cal != nullptr) {
      const fit::Region r = cal->RegionOf(idv[k], iqv[k]);
      t.extrapolated[k] |= r == fit::Region::kExtrapolated;
      t.by_symmetry[k] = !t.extrapolated[k] && r == fit::Region::kBySymmetry;
    }
    const auto L = m.Inductance(idv[k], iqv[k], lim.temperature_c);
    t.not_positive_definite[k] = !fit::NotPositiveDefiniteReason(L.ldd_h, L.lqq_h, L.ldq_h).empty();
  }
  Seal(&t);
  return t;
}

ClampSummary SummariseClamped(const Table& t) {
  ClampSummary c;
  c.cells = t.clamped.size();
  for (auto x : t.clamped) c.clamped += x;
  c.share = c.cells > 0 ? static_cast<double>(c.clamped) / c.cells : 0.0;
  if (c.clamped == 0) return c;
  const auto& l = t.limits;
  if (t.kind == "fw" && t.axes.size() == 2) {
    // The torque axis stays within the limit torque at standstill, so a
    // clamped cell is a speed at which the voltage limit leaves less.
    const auto& n = t.axes[1].values;
    size_t first = n.size();
    for (size_t k = 0; k < t.clamped.size(); ++k) {
      if (t.clamped[k]) first = std::min(first, k % n.size());
    }
    c.why = absl::StrFormat(
        "the voltage limit u_max %.4g V (Udc %.4g V, Rs %.4g ohm) leaves less torque than requested from %.0f rpm "
        "on (%zu of %zu speeds up to %.0f rpm; current limit %.4g A)",
        l.UMaxV(), l.udc_v.value_or(0.0), l.rs_ohm.value_or(0.0), n[first], n.size() - first, n.size(), n.back(),
        l.i_max_a);
  } else if (t.kind == "mtpv") {
    c.why = absl::StrFormat("the MTPV points of those fluxes lie beyond the current limit %.4g A", l.i_max_a);
  } else {
    c.why = absl::StrFormat("the torque requested exceeds the limit torque at the current limit %.4g A", l.i_max_a);
  }
  return c;
}

const char* FluxcalVersion() { return FLUXCAL_VERSION; }

std::string PayloadBytes(const Table& t) {
  std::string out;
  auto put = [&](const std::vector<double>& v) {
    for (double x : v) {
      uint64_t bits;
      std::memcpy(&bits, &x, 8);
      for (int b = 0; b < 8; ++b) out.push_back(static_cast<char>((bits >> (8 * b)) & 0xff));
    }
  };
  for (const auto& a : t.axes) put(a.values);
  for (const auto& o : t.outputs) put(o.values);
  return out;
}

void Seal(Table* t) {
  const std::string p = PayloadBytes(*t);
  t->crc32 = static_cast<uint32_t>(::crc32(0L, reinterpret_cast<const Bytef*>(p.data()),
                                           static_cast<uInt>(p.size())));
  t->sha256 = io::Sha256Hex(p);
}

absl::StatusOr<Format> ParseFormat(const std::string& name) {
  if (name == "csv") return Format::kCsv;
  if (name == "json") return Format::kJson;
  if (name == "h") return Format::kCHeader;
  if (name == "cdfx") return Format::kCdfx;
  if (name == "dcm") return Format::kDcm;
  if (name == "a2l") return Format::kA2l;
  return absl::InvalidArgumentError(
      absl::StrCat("flag --format: expected csv, json, h, cdfx, dcm or a2l, got '", name, "'"));
}

namespace {

// std::to_chars with a precision formats as printf's "%.17g" does in the C
// locale ([charconv.to.chars]), without printf's parsing of the format per
// value: a 64 x 32 CDFX map writes ~10^4 of them.
std::string Num(double v) {
  if (!std::isfinite(v)) return absl::StrFormat("%.17g", v);
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 17);
  return std::string(buf, r.ptr);
}

}  // namespace

std::string UnitOf(const std::string& name) {
  auto ends = [&](const char* suf) {
    const size_t n = std::strlen(suf);
    return name.size() > n && name.compare(name.size() - n, n, suf) == 0;
  };
  if (ends("_nm")) return "Nm";
  if (ends("_rpm")) return "rpm";
  if (ends("_wb")) return "Wb";
  if (ends("_ohm")) return "Ohm";
  if (ends("_v")) return "V";
  if (ends("_c")) return "degC";
  if (ends("_a")) return "A";
  return "-";
}

std::string Label(const Table& t, const std::string& name) {
  return absl::AsciiStrToUpper(absl::StrCat("FLUXCAL_", t.kind, "_", name));
}

std::string CSymbol(const Table& t, const std::string& name) { return absl::AsciiStrToLower(Label(t, name)); }

// One sentence on the axis order, the same in every format (docs/tables.md).
std::string AxisOrder(const Table& t) {
  if (t.axes.size() == 1) return absl::StrCat("X = ", t.axes[0].name, " (one axis)");
  return absl::StrCat("X = ", t.axes[0].name, " (first axis), Y = ", t.axes[1].name,
                      " (second axis); flat arrays index [ix * ", t.axes[1].values.size(), " + iy], X slowest");
}

// Text that goes into a comment: one line, no comment terminators.
std::string OneLine(std::string s) {
  for (auto& c : s) if (c == '\n' || c == '\r') c = ' ';
  return absl::StrReplaceAll(s, {{"*/", "* /"}, {"--", "- -"}});
}

namespace {

std::string XmlEscape(const std::string& s) {
  return absl::StrReplaceAll(s, {{"&", "&amp;"}, {"<", "&lt;"}, {">", "&gt;"}, {"\"", "&quot;"}});
}

std::string CString(const std::string& s) {
  return absl::StrCat("\"", absl::StrReplaceAll(OneLine(s), {{"\\", "\\\\"}, {"\"", "\\\""}}), "\"");
}

std::string Crc(const Table& t) { return absl::StrFormat("%08x", t.crc32); }

// The flag arrays as doubles, for the writers that treat them as tables.
std::vector<double> AsDoubles(const std::vector<uint8_t>& v) { return std::vector<double>(v.begin(), v.end()); }

std::string Csv(const Table& t) {
  // Comment header: "# key: value" lines, then one row per cell (X slowest).
  std::string s = absl::StrFormat("# fluxcal %s table\n", t.kind);
  for (const auto& [k, v] : TextFields(t)) s += absl::StrCat("# ", k, ": ", OneLine(v), "\n");
  s += absl::StrCat("# calibration_version: ", t.calibration_version, "\n");
  for (const auto& sc : Scalars(t)) {
    if (sc.name == "calibration_version") continue;
    s += absl::StrCat("# ", sc.name, ": ", Num(sc.value), " ", sc.unit, " (", sc.description, ")\n");
  }
  s += absl::StrCat("# axis_order: ", AxisOrder(t), "\n");
  s += absl::StrCat("# payload_crc32: ", Crc(t), " (over the values, docs/tables.md; not a file checksum)\n");
  s += absl::StrCat("# payload_sha256: ", t.sha256, " (over the values, docs/tables.md; not a file checksum)\n");
  std::vector<std::string> head;
  for (const auto& a : t.axes) head.push_back(a.name);
  for (const auto& o : t.outputs) head.push_back(o.name);
  for (const auto& [name, v] : Flags(t)) head.push_back(name);
  s += absl::StrJoin(head, ",") + "\n";
  const size_t n0 = t.axes[0].values.size();
  const size_t n1 = t.axes.size() > 1 ? t.axes[1].values.size() : 1;
  for (size_t i = 0; i < n0; ++i) {
    for (size_t j = 0; j < n1; ++j) {
      std::vector<std::string> row = {Num(t.axes[0].values[i])};
      if (t.axes.size() > 1) row.push_back(Num(t.axes[1].values[j]));
      for (const auto& o : t.outputs) row.push_back(Num(o.values[i * n1 + j]));
      for (const auto& [name, v] : Flags(t)) row.push_back((*v)[i * n1 + j] ? "1" : "0");
      s += absl::StrJoin(row, ",") + "\n";
    }
  }
  return s;
}

std::string Json(const Table& t) {
  nlohmann::json j;
  // v2: the checksums are named payload_crc32 / payload_sha256 (v1 called
  // them crc32 / sha256, read as file checksums), and limits, verdict,
  // release state and flags travel in the file.
  j["format"] = "fluxcal.table.v2";
  j["kind"] = t.kind;
  for (const auto& [k, v] : TextFields(t)) j[k] = v;
  j["calibration_version"] = t.calibration_version;
  nlohmann::json sc = nlohmann::json::object();
  for (const auto& x : Scalars(t)) {
    if (x.name == "calibration_version") continue;
    sc[x.name] = {{"value", x.value}, {"unit", x.unit}, {"description", x.description}};
  }
  j["scalars"] = sc;
  j["axis_order"] = AxisOrder(t);
  j["payload_crc32"] = Crc(t);
  j["payload_sha256"] = t.sha256;
  for (const auto& a : t.axes) j["axes"].push_back({{"name", a.name}, {"unit", UnitOf(a.name)}, {"values", a.values}});
  for (const auto& o : t.outputs) j["outputs"].push_back({{"name", o.name}, {"unit", UnitOf(o.name)}, {"values", o.values}});
  for (const auto& [name, v] : Flags(t)) j[name] = *v;
  return j.dump(1) + "\n";
}

// A C literal of the element type: always with a '.' or exponent, and the
// 'f' suffix for float (a bare "0f" is not C). Float keeps 9 significant
// digits, enough to round-trip a binary32 (IEEE 754-2008, 5.12.2).
std::string CNum(double v, CType ct) {
  std::string s = ct == CType::kFloat ? absl::StrFormat("%.9g", static_cast<float>(v)) : Num(v);
  if (s.find_first_of(".eE") == std::string::npos) s += ".0";
  if (ct == CType::kFloat) s += "f";
  return s;
}

// The C element type of the value arrays.
const char* CElementType(CType ct) {
  switch (ct) {
    case CType::kFloat: return "float";
    case CType::kInt16: return "int16_t";
    case CType::kInt32: return "int32_t";
    case CType::kDouble: break;
  }
  return "double";
}

// An integer literal of a fixed-point array; the type's minimum is written
// as (-max - 1): "-2147483648" is the negation of a constant too large for
// int (C99 6.4.4.1).
std::string CInt(int64_t raw, int bits) {
  const int64_t lo = -(int64_t{1} << (bits - 1));
  return raw == lo ? absl::StrCat("(", lo + 1, " - 1)") : absl::StrCat(raw);
}

absl::StatusOr<std::string> CHeader(const Table& t, CType ct, const std::vector<QuantityScale>& fixed) {
  const std::string g = Label(t, "TABLE_H_");
  const char* type = CElementType(ct);
  const int bits = FixedPointBits(ct);
  std::string s = absl::StrFormat("/* fluxcal %s table. Units: SI (A, N m, rpm, Wb, V, Ohm, degC).\n", t.kind);
  for (const auto& [k, v] : TextFields(t)) s += absl::StrCat(" * ", k, ": ", OneLine(v), "\n");
  s += absl::StrCat(" * calibration_version: ", t.calibration_version, "\n");
  for (const auto& sc : Scalars(t)) {
    if (sc.name == "calibration_version") continue;
    s += absl::StrCat(" * ", sc.name, ": ", Num(sc.value), " ", sc.unit, " (", OneLine(sc.description), ")\n");
  }
  s += absl::StrCat(" * axis order: ", AxisOrder(t), ".\n");
  std::vector<std::string> flag_names;
  for (const auto& [name, v] : Flags(t)) flag_names.push_back(Label(t, name));
  s += absl::StrCat(" * Value arrays are ", type, bits > 0 ? " fixed point (below)" : "", "; ",
                    absl::StrJoin(flag_names, " / "), " are 0/1 per cell.\n");
  if (bits > 0) {
    // docs/tables.md, "Fixed point": one power-of-two LSB per quantity.
    s += absl::StrCat(" * Fixed point: physical = raw * LSB + offset, raw the ", type,
                      " value rounded to the nearest\n * integer (error at most LSB/2); <ARRAY>_LSB states each array's LSB:\n");
    for (const auto& q : fixed) {
      s += absl::StrFormat(" *   %s: LSB %s %s (2^%d), offset %s %s, range %s .. %s %s: %s\n", q.unit, Num(q.lsb),
                           q.unit, static_cast<int>(std::lround(std::log2(q.lsb))), Num(q.offset), q.unit,
                           Num(q.min_value), Num(q.max_value), q.unit, absl::StrJoin(q.arrays, ", "));
    }
  }
  s += " * payload_crc32 / payload_sha256: over the values as IEEE-754 binary64 (fluxcal docs/tables.md),\n"
       " * not over this file";
  if (ct == CType::kFloat) s += "; the float arrays hold those values rounded to binary32";
  if (bits > 0) s += absl::StrCat("; the ", type, " arrays hold them rounded to the nearest LSB");
  s += ". */\n";
  s += absl::StrFormat("#ifndef %s\n#define %s\n\n#include <stdint.h>\n\n", g, g);
  for (const auto& sc : Scalars(t)) {
    s += absl::StrFormat("#define %s %s\n", Label(t, sc.name),
                         sc.integer ? absl::StrCat(static_cast<long long>(sc.value)) : CNum(sc.value, ct));
  }
  s += "\n";
  for (const auto& [k, v] : TextFields(t)) {
    s += absl::StrFormat("static const char %s[] = %s;\n", CSymbol(t, k), CString(v));
  }
  s += "\n";
  auto arr = [&](const std::string& name, const std::vector<double>& v, const char* ty, bool flag) -> absl::Status {
    std::vector<std::string> lit(v.size());
    const QuantityScale* q = flag ? nullptr : ScaleOf(fixed, name);
    s += absl::StrFormat("#define %s_LEN %d\n", Label(t, name), v.size());
    if (bits > 0 && q != nullptr) {
      auto raw = Quantize(v, *q, absl::StrCat("table array '", name, "'"));
      if (!raw.ok()) return raw.status();
      for (size_t k = 0; k < v.size(); ++k) lit[k] = CInt((*raw)[k], bits);
      s += absl::StrFormat("#define %s_LSB %s\n", Label(t, name), CNum(q->lsb, CType::kDouble));
    } else {
      for (size_t k = 0; k < v.size(); ++k) lit[k] = flag ? (v[k] != 0 ? "1" : "0") : CNum(v[k], ct);
    }
    s += absl::StrFormat("static const %s %s[%d] = {\n", ty, CSymbol(t, name), v.size());
    for (size_t k = 0; k < v.size(); ++k) s += absl::StrCat("  ", lit[k], k + 1 < v.size() ? ",\n" : "\n");
    s += "};\n\n";
    return absl::OkStatus();
  };
  for (const auto& a : t.axes) {
    if (auto st = arr(a.name, a.values, type, false); !st.ok()) return st;
  }
  for (const auto& o : t.outputs) {
    if (auto st = arr(o.name, o.values, type, false); !st.ok()) return st;
  }
  for (const auto& [name, v] : Flags(t)) {
    if (auto st = arr(name, AsDoubles(*v), "uint8_t", true); !st.ok()) return st;
  }
  s += absl::StrFormat("static const uint32_t %s = 0x%08xu;\n", CSymbol(t, "payload_crc32"), t.crc32);
  s += absl::StrFormat("static const char %s[] = \"%s\";\n\n#endif\n",
                       CSymbol(t, "payload_sha256"), t.sha256);
  return s;
}

std::string Cdfx(const Table& t) {
  // ASAM CDF 2.0 (MSRSW): MSRSW > SW-SYSTEMS > SW-SYSTEM > SW-INSTANCE-SPEC >
  // SW-INSTANCE-TREE > SW-INSTANCE. Scalars are category VALUE (V), text
  // ASCII (VT), outputs and flags CURVE (1 axis) or MAP (2 axes) with
  // STD_AXIS containers in axis order X, Y; a MAP holds one VG per X value
  // with the values over Y. The subset emitted is described by
  // tests/tables/cdf_subset.dtd.
  std::string s =
      "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      "<!DOCTYPE MSRSW PUBLIC \"-//ASAM//DTD CALIBRATION DATA FORMAT:V2.0.0:LAI:IAI:XML:CDF200.XSD//EN\" \"cdf_v2.0.0.sl.dtd\">\n";
  s += absl::StrCat("<!-- fluxcal ", t.kind, " table; axis order: ", OneLine(AxisOrder(t)), ". payload_crc32 ", Crc(t),
                    ", payload_sha256 ", t.sha256, ": over the values (fluxcal docs/tables.md), not over this file. -->\n");
  s += "<MSRSW>\n  <SHORT-NAME>fluxcal</SHORT-NAME>\n  <CATEGORY>CDF20</CATEGORY>\n  <SW-SYSTEMS>\n    <SW-SYSTEM>\n";
  s += absl::StrFormat("      <SHORT-NAME>%s</SHORT-NAME>\n", XmlEscape(t.serial.empty() ? "fluxcal" : t.serial));
  s += "      <SW-INSTANCE-SPEC>\n        <SW-INSTANCE-TREE>\n          <SHORT-NAME>fluxcal</SHORT-NAME>\n"
       "          <CATEGORY>NO_VCD</CATEGORY>\n";
  const std::string in = "          ";
  auto head = [&](const std::string& name, const std::string& long_name, const char* cat) {
    s += absl::StrCat(in, "<SW-INSTANCE>\n", in, "  <SHORT-NAME>", Label(t, name), "</SHORT-NAME>\n", in,
                      "  <LONG-NAME>", XmlEscape(OneLine(long_name)), "</LONG-NAME>\n", in, "  <CATEGORY>", cat,
                      "</CATEGORY>\n");
  };
  for (const auto& sc : Scalars(t)) {
    head(sc.name, sc.description, "VALUE");
    s += absl::StrCat(in, "  <SW-VALUE-CONT>\n", in, "    <UNIT-DISPLAY-NAME>", sc.unit, "</UNIT-DISPLAY-NAME>\n", in,
                      "    <SW-VALUES-PHYS><V>", Num(sc.value), "</V></SW-VALUES-PHYS>\n", in, "  </SW-VALUE-CONT>\n", in,
                      "</SW-INSTANCE>\n");
  }
  for (const auto& [k, v] : TextFields(t)) {
    head(k, k, "ASCII");
    s += absl::StrCat(in, "  <SW-VALUE-CONT>\n", in, "    <SW-VALUES-PHYS><VT>", XmlEscape(OneLine(v)),
                      "</VT></SW-VALUES-PHYS>\n", in, "  </SW-VALUE-CONT>\n", in, "</SW-INSTANCE>\n");
  }
  const bool map = t.axes.size() > 1;
  const size_t n0 = t.axes[0].values.size(), n1 = map ? t.axes[1].values.size() : 1;
  auto table = [&](const std::string& name, const std::string& unit, const std::vector<double>& vals,
                   const std::string& what) {
    head(name, what, map ? "MAP" : "CURVE");
    s += absl::StrCat(in, "  <SW-VALUE-CONT>\n", in, "    <UNIT-DISPLAY-NAME>", unit, "</UNIT-DISPLAY-NAME>\n", in,
                      "    <SW-VALUES-PHYS>\n");
    for (size_t i = 0; i < n0; ++i) {
      if (map) s += absl::StrCat(in, "      <VG>\n");
      for (size_t j = 0; j < n1; ++j) {
        s += absl::StrCat(in, map ? "        " : "      ", "<V>", Num(vals[i * n1 + j]), "</V>\n");
      }
      if (map) s += absl::StrCat(in, "      </VG>\n");
    }
    s += absl::StrCat(in, "    </SW-VALUES-PHYS>\n", in, "  </SW-VALUE-CONT>\n", in, "  <SW-AXIS-CONTS>\n");
    for (const auto& a : t.axes) {
      s += absl::StrCat(in, "    <SW-AXIS-CONT>\n", in, "      <CATEGORY>STD_AXIS</CATEGORY>\n", in,
                        "      <UNIT-DISPLAY-NAME>", UnitOf(a.name), "</UNIT-DISPLAY-NAME>\n", in,
                        "      <SW-VALUES-PHYS>\n");
      for (double v : a.values) s += absl::StrCat(in, "        <V>", Num(v), "</V>\n");
      s += absl::StrCat(in, "      </SW-VALUES-PHYS>\n", in, "    </SW-AXIS-CONT>\n");
    }
    s += absl::StrCat(in, "  </SW-AXIS-CONTS>\n", in, "</SW-INSTANCE>\n");
  };
  std::vector<std::string> axis_names;
  for (const auto& a : t.axes) axis_names.push_back(a.name);
  const std::string over = absl::StrJoin(axis_names, " x ");
  for (const auto& o : t.outputs) table(o.name, UnitOf(o.name), o.values, absl::StrCat(o.name, " over ", over));
  for (const auto& [name, v] : Flags(t)) {
    table(name, "-", AsDoubles(*v), absl::StrCat(name, " (0/1 per cell) over ", over));
  }
  s += "        </SW-INSTANCE-TREE>\n      </SW-INSTANCE-SPEC>\n    </SW-SYSTEM>\n  </SW-SYSTEMS>\n</MSRSW>\n";
  return s;
}

std::string Dcm(const Table& t) {
  // DAMOS DCM 2.0 (KONSERVIERUNG_FORMAT 2.0): FESTWERT (scalar), KENNLINIE
  // (curve) and KENNFELD (map) blocks, 6 values a line; text metadata as
  // '*' comments (DCM has no text scalar every tool accepts).
  std::string s = absl::StrFormat("* fluxcal %s table\n", t.kind);
  for (const auto& [k, v] : TextFields(t)) s += absl::StrCat("* ", k, ": ", OneLine(v), "\n");
  s += absl::StrCat("* axis_order: ", AxisOrder(t), "\n");
  s += absl::StrCat("* payload_crc32: ", Crc(t), ", payload_sha256: ", t.sha256,
                    " (over the values, fluxcal docs/tables.md; not over this file)\n\nKONSERVIERUNG_FORMAT 2.0\n\n");
  auto line = [&](const std::string& key, const std::vector<double>& v) {
    for (size_t k = 0; k < v.size(); k += 6) {
      s += absl::StrCat("   ", key);
      for (size_t m = k; m < std::min(v.size(), k + 6); ++m) s += absl::StrCat(" ", Num(v[m]));
      s += "\n";
    }
  };
  for (const auto& sc : Scalars(t)) {
    s += absl::StrFormat("FESTWERT %s\n   LANGNAME \"%s\"\n   EINHEIT_W \"%s\"\n   WERT %s\nEND\n\n", Label(t, sc.name),
                         absl::StrReplaceAll(OneLine(sc.description), {{"\"", "'"}}), sc.unit, Num(sc.value));
  }
  const bool map = t.axes.size() > 1;
  const size_t n0 = t.axes[0].values.size(), n1 = map ? t.axes[1].values.size() : 1;
  auto block = [&](const std::string& name, const std::string& unit, const std::vector<double>& vals) {
    if (!map) {
      s += absl::StrFormat("KENNLINIE %s %d\n   LANGNAME \"%s over %s\"\n   EINHEIT_X \"%s\"\n   EINHEIT_W \"%s\"\n",
                           Label(t, name), n0, name, t.axes[0].name, UnitOf(t.axes[0].name), unit);
      line("ST/X", t.axes[0].values);
      line("WERT", vals);
    } else {
      // KENNFELD name nx ny: ST/X the X axis (first axis), then per Y value
      // (second axis) one ST/Y line and the WERT values over X.
      s += absl::StrFormat("KENNFELD %s %d %d\n   LANGNAME \"%s over %s x %s\"\n   EINHEIT_X \"%s\"\n   EINHEIT_Y \"%s\"\n   EINHEIT_W \"%s\"\n",
                           Label(t, name), n0, n1, name, t.axes[0].name, t.axes[1].name, UnitOf(t.axes[0].name),
                           UnitOf(t.axes[1].name), unit);
      line("ST/X", t.axes[0].values);
      for (size_t j = 0; j < n1; ++j) {
        s += absl::StrCat("   ST/Y ", Num(t.axes[1].values[j]), "\n");
        std::vector<double> row(n0);
        for (size_t i = 0; i < n0; ++i) row[i] = vals[i * n1 + j];
        line("WERT", row);
      }
    }
    s += "END\n\n";
  };
  for (const auto& o : t.outputs) block(o.name, UnitOf(o.name), o.values);
  for (const auto& [name, v] : Flags(t)) block(name, "-", AsDoubles(*v));
  return s;
}

}  // namespace

std::vector<Scalar> Scalars(const Table& t) {
  const auto& l = t.limits;
  // Rs, Udc and u_max only when they were given: an MTPA table computed
  // without them does not state a voltage it never used.
  std::vector<Scalar> s = {
      {"pole_pairs", static_cast<double>(l.pole_pairs), "-", "pole pairs p of the calibration", true}};
  if (l.rs_ohm) s.push_back({"rs_ohm", *l.rs_ohm, "Ohm", "phase resistance Rs used for the steady-state voltage", false});
  s.push_back({"psi_pm_wb", t.psi_pm_wb, "Wb", "permanent-magnet flux linkage psi_d(0, 0) of the fitted model", false});
  s.push_back({"i_max_a", l.i_max_a, "A", "current limit the table was computed for (peak, amplitude-invariant)", false});
  if (l.udc_v) {
    s.push_back({"udc_v", *l.udc_v, "V", "DC-link voltage the table was computed for", false});
    s.push_back({"modulation_limit", l.modulation_limit, "-", "fraction of the linear SVPWM range used", false});
    s.push_back({"u_max_v", l.UMaxV(), "V", "voltage limit m Udc / sqrt(3) (peak phase, amplitude-invariant)", false});
  }
  s.push_back({"temperature_c", l.temperature_c, "degC", "temperature the flux model was evaluated at", false});
  if (t.measured_current_limit_a > 0) {
    s.push_back({"measured_current_limit_a", t.measured_current_limit_a, "A",
                 "current limit the identified points cover; beyond it cells are flagged extrapolated", false});
  }
  if (t.kind == "fw") {
    s.push_back({"speed_max_rpm", t.speed_max_rpm, "rpm", "top of the speed axis (axis from 0 rpm)", false});
  }
  s.push_back({"allow_extrapolation", t.allow_extrapolation ? 1.0 : 0.0, "-",
               "1: computed beyond the measured region on request (allow-extrapolation flag)", true});
  s.push_back({"calibration_version", static_cast<double>(t.calibration_version), "-",
               "stored version of the calibration", true});
  return s;
}

std::vector<std::pair<std::string, std::string>> TextFields(const Table& t) {
  return {{"serial", t.serial},           {"model", t.model},     {"created_utc", t.created_utc},
          {"fluxcal_version", t.fluxcal_version}, {"verdict", t.verdict}, {"release_state", t.release_state}};
}

std::vector<std::pair<std::string, const std::vector<uint8_t>*>> Flags(const Table& t) {
  return {{"clamped", &t.clamped},
          {"extrapolated", &t.extrapolated},
          {"by_symmetry", &t.by_symmetry},
          {"not_positive_definite", &t.not_positive_definite}};
}

absl::StatusOr<CType> ParseCType(const std::string& name) {
  for (CType ct : {CType::kDouble, CType::kFloat, CType::kInt16, CType::kInt32}) {
    if (name == CTypeName(ct)) return ct;
  }
  return absl::InvalidArgumentError(
      absl::StrCat("flag --ctype: expected double, float, int16 or int32, got '", name, "'"));
}

const char* CTypeName(CType ct) {
  switch (ct) {
    case CType::kFloat: return "float";
    case CType::kInt16: return "int16";
    case CType::kInt32: return "int32";
    case CType::kDouble: break;
  }
  return "double";
}

int FixedPointBits(CType ct) { return ct == CType::kInt16 ? 16 : ct == CType::kInt32 ? 32 : 0; }

absl::StatusOr<Exported> Export(const Table& t, Format f, const ExportOptions& opt) {
  if (t.axes.empty() || t.outputs.empty()) return absl::InvalidArgumentError("table: no axes or no outputs");
  size_t cells = 1;
  for (const auto& a : t.axes) {
    cells *= a.values.size();
    for (double v : a.values) {
      if (!std::isfinite(v)) return absl::InvalidArgumentError(absl::StrCat("table axis '", a.name, "': non-finite value"));
    }
  }
  for (const auto& o : t.outputs) {
    if (o.values.size() != cells) {
      return absl::InvalidArgumentError(absl::StrCat("table output '", o.name, "': ", o.values.size(),
                                                     " values for ", cells, " cells"));
    }
    for (double v : o.values) {
      if (!std::isfinite(v)) return absl::InvalidArgumentError(absl::StrCat("table output '", o.name, "': non-finite value"));
    }
  }
  for (const auto& [name, v] : Flags(t)) {
    if (v->size() != cells) {
      return absl::InvalidArgumentError(absl::StrCat("table flags '", name, "': ", v->size(), " for ", cells, " cells"));
    }
  }
  Exported e;
  const std::vector<QuantityScale> scales = QuantityScales(t, opt.ctype);
  if ((f == Format::kCHeader || f == Format::kA2l) && FixedPointBits(opt.ctype) > 0) e.fixed_point = scales;
  switch (f) {
    case Format::kCsv: e.bytes = Csv(t); break;
    case Format::kJson: e.bytes = Json(t); break;
    case Format::kCHeader: {
      auto h = CHeader(t, opt.ctype, scales);
      if (!h.ok()) return h.status();
      e.bytes = *std::move(h);
      break;
    }
    case Format::kCdfx: e.bytes = Cdfx(t); break;
    case Format::kDcm: e.bytes = Dcm(t); break;
    case Format::kA2l: {
      e.bytes = A2lDescription(t, opt.ctype, scales);
      break;
    }
  }
  e.payload_crc32 = t.crc32;
  e.payload_sha256 = t.sha256;
  e.file_sha256 = io::Sha256Hex(e.bytes);
  return e;
}

namespace {

double RpmOf(double we_rad_s, int pole_pairs) { return physics::ElectricalRadSToRpm(we_rad_s, pole_pairs); }

// Base speed: where the MTPA point of the largest motoring torque meets the
// voltage limit (bisection; the voltage grows with speed there). 0 when the
// limit is below the resistive drop already at standstill.
double BaseSpeedRadS(const sim::MagneticModel& m, const MachineLimits& lim, const Table& mtpa) {
  size_t kmax = 0;
  for (size_t k = 0; k < mtpa.axes[0].values.size(); ++k) {
    if (mtpa.axes[0].values[k] > mtpa.axes[0].values[kmax]) kmax = k;
  }
  const double id = mtpa.outputs[0].values[kmax], iq = mtpa.outputs[1].values[kmax];
  double lo = 0, hi = 1e6;
  if (VoltageV(m, lim, id, iq, lo) >= lim.UMaxV()) return 0;
  if (VoltageV(m, lim, id, iq, hi) < lim.UMaxV()) return hi;
  for (int k = 0; k < 80; ++k) {
    const double mid = 0.5 * (lo + hi);
    (VoltageV(m, lim, id, iq, mid) < lim.UMaxV() ? lo : hi) = mid;
  }
  return lo;
}

// The motoring rows of an MTPA or MTPV table as points of its curve, with
// their flags. MTPV rows the solver could not place (no torque, or id at
// its search bound of -2 i_max) are not points of the curve.
struct CurvePoints {
  std::vector<double> id, iq, cid, ciq, eid, eiq;   // all; clamped; extrapolated
  size_t rows = 0;
};
CurvePoints MotoringRows(const Table& t) {
  CurvePoints c;
  if (t.outputs.size() < 2) return c;
  const double im = t.limits.i_max_a;
  for (size_t k = 0; k < t.outputs[0].values.size(); ++k) {
    const double id = t.outputs[0].values[k], iq = t.outputs[1].values[k];
    if (iq < 0) continue;
    if (t.kind == "mtpv" && (t.outputs.size() < 3 || !(t.outputs[2].values[k] > 0) || id < -1.99 * im)) continue;
    c.id.push_back(id);
    c.iq.push_back(iq);
    if (k < t.clamped.size() && t.clamped[k]) c.cid.push_back(id), c.ciq.push_back(iq);
    if (k < t.extrapolated.size() && t.extrapolated[k]) c.eid.push_back(id), c.eiq.push_back(iq);
  }
  c.rows = c.id.size();
  return c;
}

// Marker styles shared by the curve and map figures: clamped (the request
// exceeded the limits) and extrapolated (beyond the measured current
// limit) must not look like valid entries.
plot::Style MarkStyle(plot::Marker marker, const char* colour, const char* halo, double size_px) {
  plot::Style s;
  s.marker = marker;
  s.colour = colour;
  s.halo = halo;
  s.marker_px = size_px;
  return s;
}
plot::Style ClampedStyle(double size_px) { return MarkStyle(plot::Marker::kCross, "#000000", "#ffffff", size_px); }
plot::Style ExtrapolatedStyle(double size_px) {
  return MarkStyle(plot::Marker::kSquare, "#ffffff", "#000000", size_px);
}

}  // namespace

namespace {

// Speed [rad/s electrical] at which the voltage limit passes through (id,
// iq): the voltage grows with speed there. 0 when no speed reaches it (the
// resistive drop alone exceeds u_max).
double SpeedAtVoltageLimitRadS(const sim::MagneticModel& m, const MachineLimits& lim, double id, double iq) {
  double lo = 0, hi = 1e6;
  if (VoltageV(m, lim, id, iq, lo) >= lim.UMaxV()) return 0;
  if (VoltageV(m, lim, id, iq, hi) < lim.UMaxV()) return hi;
  for (int k = 0; k < 80; ++k) {
    const double mid = 0.5 * (lo + hi);
    (VoltageV(m, lim, id, iq, mid) < lim.UMaxV() ? lo : hi) = mid;
  }
  return lo;
}

// The current plane with both tables; `mtpv_subject` decides whose figure
// it is: that table is drawn bold with a dot per row and the voltage limit
// at the speed that explains it, the other thin, for reference.
std::string CurvesFigure(const sim::MagneticModel& m, const MachineLimits& lim, const Table* mtpa, const Table* mtpv,
                         bool mtpv_subject) {
  const double im = lim.i_max_a;
  const Table& subject = mtpv_subject ? *mtpv : *mtpa;
  const CurvePoints pa = mtpa != nullptr ? MotoringRows(*mtpa) : CurvePoints{};
  const CurvePoints pv = mtpv != nullptr ? MotoringRows(*mtpv) : CurvePoints{};
  // View: the motoring quadrant of the current limit, widened to the MTPV
  // points up to 1.6 i_max (MTPV usually lies at id < -i_max); rows beyond
  // are counted in the legend.
  double x_lo = -1.1 * im;
  for (double d : pv.id) {
    if (d >= -1.6 * im) x_lo = std::min(x_lo, 1.05 * d);
  }
  const double x_hi = 0.1 * im, y_hi = 1.15 * im;
  plot::Figure f(mtpv_subject ? "mtpv-curves" : "mtpa-curves", 820, 860);
  // Below the axes: the equal-aspect view wants the width, the legend
  // names speeds, limits and row counts.
  f.SetLegendBelow(true);
  f.SetTitle(absl::StrFormat("%s%s%s table on the current plane (motoring half)%s", subject.serial,
                             subject.serial.empty() ? "" : ": ", mtpv_subject ? "MTPV" : "MTPA",
                             (mtpv_subject ? mtpa : mtpv) != nullptr
                                 ? (mtpv_subject ? ", MTPA for reference" : ", MTPV for reference")
                                 : ""));
  f.SetXLabel("id [A]");
  f.SetYLabel("iq [A]");
  f.SetXRange(x_lo, x_hi);
  f.SetYRange(0, y_hi);
  f.SetEqualAspect(true);
  f.SetTight(true, true);
  // Fields sampled well beyond the view (equal scaling widens one axis);
  // the figure clips the lines at its frame.
  const double field_id_lo_a = std::min(x_lo, -2.0 * im) - 0.2 * im, field_iq_hi_a = 2.2 * im;
  // The voltage limit at a speed that explains the subject. MTPA: 1.5 x
  // base speed, rounded to two digits, far enough into field weakening that
  // it cuts the current circle. MTPV: the speed at which MTPV operation
  // begins, where the limit passes through the MTPV row of largest current
  // within the current limit (its point on the circle, if it reaches it).
  double rpm = 0;
  std::string why, no_voltage, unknown_voltage;
  if (!lim.HasVoltageLimit()) {
    unknown_voltage = absl::StrCat("no voltage limit drawn: ", !lim.udc_v ? "the DC-link voltage (--udc-v)" : "",
                                   !lim.udc_v && !lim.rs_ohm ? " and " : "", !lim.rs_ohm ? "Rs (--rs-ohm)" : "",
                                   " not known");
  } else if (!mtpv_subject) {
    const double we_base = BaseSpeedRadS(m, lim, *mtpa);
    if (we_base > 0) {
      const double raw = 1.5 * RpmOf(we_base, lim.pole_pairs);
      const double mag = std::pow(10.0, std::floor(std::log10(std::max(raw, 1.0))) - 1);
      rpm = std::round(raw / mag) * mag;
      why = absl::StrFormat(" (1.5 x base speed %.0f rpm)", RpmOf(we_base, lim.pole_pairs));
    } else {
      no_voltage = "below the resistive drop at full MTPA current";
    }
  } else {
    int start = -1;
    for (size_t k = 0; k < pv.rows; ++k) {
      const double i = std::hypot(pv.id[k], pv.iq[k]);
      if (i <= im * (1 + 1e-9) && (start < 0 || i > std::hypot(pv.id[start], pv.iq[start]))) {
        start = static_cast<int>(k);
      }
    }
    if (start >= 0) {
      const double we_start = SpeedAtVoltageLimitRadS(m, lim, pv.id[start], pv.iq[start]);
      if (we_start > 0) {
        rpm = RpmOf(we_start, lim.pole_pairs);
        why = absl::StrFormat(", where MTPV begins (its row at |i| = %.4g A)", std::hypot(pv.id[start], pv.iq[start]));
      } else {
        no_voltage = "below the resistive drop at the MTPV rows";
      }
    } else {
      no_voltage.clear();   // said below: no MTPV row inside the current limit
    }
  }
  const double we = physics::RpmToElectricalRadS(rpm, lim.pole_pairs);
  const PlaneCircle circle = DrawCurrentPlane(
      &f, m, lim, field_id_lo_a, field_iq_hi_a, rpm > 0 ? we : 0.0,
      absl::StrFormat("voltage limit |u| = %.3g V at %.0f rpm%s", lim.UMaxV(), rpm, why));
  const std::vector<double>& cx = circle.id_a;
  const std::vector<double>& cy = circle.iq_a;
  const double meas = subject.measured_current_limit_a;
  if (meas > 0 && std::abs(meas - im) > 1e-6 * im) {
    plot::Style mc;
    mc.colour = "#2ca02c";
    mc.width_px = 1.2;
    mc.dash = "2 3";
    std::vector<double> mx, my;
    for (double x : cx) mx.push_back(x * meas / im);
    for (double y : cy) my.push_back(y * meas / im);
    f.Line(mx, my, mc, absl::StrFormat("measured current limit %.4g A", meas));
  }
  if (rpm > 0) {
    // drawn with the plane (DrawCurrentPlane)
  } else if (!unknown_voltage.empty()) {
    f.Note(unknown_voltage);
  } else if (!no_voltage.empty()) {
    f.Note(absl::StrFormat("no voltage limit drawn: u_max %.3g V is %s", lim.UMaxV(), no_voltage));
  } else {
    f.Note("no voltage limit drawn: no MTPV row lies inside the current limit");
  }
  auto beyond = [&](const CurvePoints& c) {
    size_t n = 0;
    for (size_t k = 0; k < c.rows; ++k) n += c.id[k] < x_lo || c.iq[k] > y_hi;
    return n == 0 ? std::string() : absl::StrFormat(", %zu beyond the view", n);
  };
  // The tables as lines through their rows, MTPA red, MTPV blue; the
  // subject bold with each row a dot sized to the rows' spacing (dense rows
  // would merge into a thick line), the other thin.
  const double px_per_a = 700 / std::max(x_hi - x_lo, y_hi);   // about the plot area's width
  size_t clamped = 0, extrapolated = 0;
  auto draw = [&](const CurvePoints& c, const std::string& colour, bool is_subject, const std::string& label) {
    plot::Style line;
    line.colour = colour;
    line.width_px = is_subject ? 2.6 : 1.4;
    f.Line(c.id, c.iq, line, is_subject ? label : label + ", for reference");
    if (!is_subject) return;
    double length = 0;
    for (size_t k = 1; k < c.rows; ++k) length += std::hypot(c.id[k] - c.id[k - 1], c.iq[k] - c.iq[k - 1]);
    plot::Style rows = line;
    rows.halo.clear();
    rows.marker_px = std::clamp(0.3 * length * px_per_a / std::max<size_t>(1, c.rows - 1), 1.2, 3.0);
    f.Scatter(c.id, c.iq, rows, "");
    clamped += c.cid.size();
    extrapolated += c.eid.size();
  };
  if (pa.rows > 0) {
    draw(pa, "#d62728", !mtpv_subject,
         absl::StrFormat("MTPA table (%zu motoring rows%s)", pa.rows, beyond(pa)));
  }
  if (pv.rows > 0) {
    const auto& psi = mtpv->axes[0].values;
    draw(pv, "#1f77b4", mtpv_subject,
         absl::StrFormat("MTPV table (%zu rows, |psi| %.3g .. %.3g Wb%s)", pv.rows, psi.front(), psi.back(),
                         beyond(pv)));
  } else {
    f.Note(mtpv == nullptr ? "no MTPV table given" : "the MTPV table has no row with positive torque to draw");
  }
  // The subject's flags on top of the rows they concern.
  std::vector<double> fx, fy, ex, ey;
  for (const CurvePoints* c : {mtpv_subject ? &pv : &pa}) {
    fx.insert(fx.end(), c->cid.begin(), c->cid.end());
    fy.insert(fy.end(), c->ciq.begin(), c->ciq.end());
    ex.insert(ex.end(), c->eid.begin(), c->eid.end());
    ey.insert(ey.end(), c->eiq.begin(), c->eiq.end());
  }
  if (clamped > 0) {
    f.Scatter(fx, fy, ClampedStyle(4), absl::StrFormat("clamped rows (%zu): beyond the limits", clamped));
  }
  if (extrapolated > 0) {
    f.Scatter(ex, ey, ExtrapolatedStyle(4),
              absl::StrFormat("extrapolated rows (%zu): |i| beyond the measured %.4g A", extrapolated, meas));
  }
  return f.Svg();
}

}  // namespace

PlaneCircle DrawCurrentPlane(plot::Figure* f, const sim::MagneticModel& m, const MachineLimits& lim, double id_lo_a,
                             double iq_hi_a, double we_rad_s, const std::string& voltage_label, bool generating) {
  const double im = lim.i_max_a;
  if (!lim.HasVoltageLimit()) we_rad_s = 0;   // no voltage limit without Udc and Rs
  const auto xs = Linspace(id_lo_a, 0.6 * im, 161);
  const auto ys = generating ? Linspace(-iq_hi_a, iq_hi_a, 241) : Linspace(-0.2 * im, iq_hi_a, 121);
  std::vector<double> tz, uz;
  double tmax = 0, tmin = 0;
  for (double iq : ys) {
    for (double id : xs) {
      const double t = TorqueNm(m, lim.pole_pairs, id, iq, lim.temperature_c);
      tz.push_back(t);
      if (we_rad_s > 0) uz.push_back(VoltageV(m, lim, id, iq, we_rad_s));
      if (std::hypot(id, iq) <= im) tmax = std::max(tmax, t), tmin = std::min(tmin, t);
    }
  }
  // Torque contours at round values inside the current limit's torque
  // (and, generating, the same steps below zero down to its torque there).
  std::vector<double> levels;
  const auto ticks = plot::NiceTicks(0, tmax, 6);
  for (double v : ticks) {
    if (v > 0 && v <= tmax) levels.push_back(v);
  }
  if (generating && ticks.size() > 1) {
    const double step = ticks[1] - ticks[0];
    for (double v = -step; v >= tmin - 1e-9 * step; v -= step) levels.push_back(v);
  }
  plot::Style contour;
  contour.colour = "#888888";
  contour.width_px = 1;
  f->Contours(xs, ys, tz, levels, contour, "constant torque [N m] (labelled)", "%g");
  plot::Style circle;
  circle.colour = "#000000";
  circle.dash = "6 4";
  PlaneCircle c;
  const int n = generating ? 240 : 120;
  for (int k = 0; k <= n; ++k) {
    const double a = kPi / 2 + kPi / 2 * k / 120;
    c.id_a.push_back(im * std::cos(a));
    c.iq_a.push_back(im * std::sin(a));
  }
  f->Line(c.id_a, c.iq_a, circle, absl::StrFormat("current limit |i| = %.4g A", im));
  if (we_rad_s > 0) {
    plot::Style volt;
    volt.colour = "#ff7f0e";
    volt.width_px = 2;
    volt.dash = "2 3";
    f->Contours(xs, ys, uz, {lim.UMaxV()}, volt, voltage_label, "");
  }
  return c;
}

std::string PlotCurvesSvg(const sim::MagneticModel& m, const MachineLimits& lim, const Table& mtpa,
                          const Table* mtpv) {
  return CurvesFigure(m, lim, &mtpa, mtpv, false);
}

std::string PlotMtpvSvg(const sim::MagneticModel& m, const MachineLimits& lim, const Table& mtpv,
                        const Table* mtpa) {
  return CurvesFigure(m, lim, mtpa, &mtpv, true);
}

std::string PlotMapSvg(const Table& fw, const std::string& output_name) {
  const Output* o = nullptr;
  for (const auto& out : fw.outputs) if (out.name == output_name) o = &out;
  if (o == nullptr || fw.axes.size() != 2) return "";
  const auto& tq = fw.axes[0].values;   // rows (slowest)
  const auto& n = fw.axes[1].values;    // columns
  if (tq.empty() || n.empty() || o->values.size() != tq.size() * n.size()) return "";
  const std::string quantity = output_name.substr(0, output_name.rfind('_'));
  const double width = 900, height = 640;
  plot::Figure f("fw-map", width, height);
  // Below the axes: the map gets the width.
  f.SetLegendBelow(true);
  f.SetTitle(absl::StrFormat("%s%sfield-weakening table: %s over speed and torque request", fw.serial,
                             fw.serial.empty() ? "" : ": ", quantity));
  f.SetXLabel(absl::StrFormat("speed [%s]", UnitOf(fw.axes[1].name)));
  const std::string torque_unit = UnitOf(fw.axes[0].name);
  f.SetYLabel(absl::StrFormat("torque request [%s]", torque_unit == "Nm" ? "N m" : torque_unit));
  plot::HeatOptions opt;
  opt.colour_label = absl::StrFormat("%s [%s]", quantity, UnitOf(output_name));
  std::vector<double> cx, cy, ex, ey;
  for (size_t i = 0; i < tq.size(); ++i) {
    for (size_t j = 0; j < n.size(); ++j) {
      const size_t k = i * n.size() + j;
      const bool c = k < fw.clamped.size() && fw.clamped[k], e = k < fw.extrapolated.size() && fw.extrapolated[k];
      opt.cell_titles.push_back(absl::StrFormat("%.4g N m, %.0f rpm: %s = %.4g %s%s%s", tq[i], n[j], quantity,
                                                o->values[k], UnitOf(output_name), c ? ", clamped" : "",
                                                e ? ", extrapolated" : ""));
      if (c) cx.push_back(n[j]), cy.push_back(tq[i]);
      if (e) ex.push_back(n[j]), ey.push_back(tq[i]);
    }
  }
  // The table is row-major over (torque, speed): speed is the grid's x.
  f.Heatmap(n, tq, o->values, std::move(opt));
  // Markers sized to the cells (the plot area is about 80 % x 75 % of the
  // figure), so that one marks one cell and leaves its colour visible.
  const double cell_px = std::min(0.8 * width / n.size(), 0.75 * height / tq.size());
  const double size = std::clamp(0.3 * cell_px, 1.5, 4.0);
  if (!cx.empty()) {
    f.Scatter(cx, cy, ClampedStyle(size), absl::StrFormat("clamped (%zu cells): request beyond the limits", cx.size()));
  } else {
    f.Note("no clamped cell");
  }
  if (!ex.empty()) {
    f.Scatter(ex, ey, ExtrapolatedStyle(size),
              absl::StrFormat("extrapolated (%zu cells): |i| beyond the measured %.4g A", ex.size(),
                              fw.measured_current_limit_a));
  } else {
    f.Note(fw.measured_current_limit_a > 0 ? "no extrapolated cell" : "extrapolation not checked (no measured limit)");
  }
  return f.Svg();
}

}  // namespace fluxcal::tables
