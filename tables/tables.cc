#include "tables/tables.h"

#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <ctime>
#include <numbers>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "nlohmann/json.hpp"
#include "io/sha256.h"

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
    // One flux evaluation per iteration serves both T and dT/diq.
    const auto F = m.Flux(id, s * iq, lim.temperature_c);
    const double f = s * 1.5 * lim.pole_pairs * (F.psi_d_wb * s * iq - F.psi_q_wb * id) - target;
    if (std::abs(f) < 1e-10 * (1.0 + target)) break;
    if (f > 0) hi = iq; else lo = iq;
    const auto L = m.Inductance(id, s * iq, lim.temperature_c);
    const double d = 1.5 * lim.pole_pairs * (F.psi_d_wb + L.ldq_h * s * iq - L.lqq_h * id);
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

double MachineLimits::UMaxV() const { return modulation_limit * udc_v / std::sqrt(3.0); }

double TorqueNm(const sim::MagneticModel& m, int pp, double id, double iq, double temperature_c) {
  const auto f = m.Flux(id, iq, temperature_c);
  return 1.5 * pp * (f.psi_d_wb * iq - f.psi_q_wb * id);
}

double VoltageV(const sim::MagneticModel& m, const MachineLimits& lim, double id, double iq, double we) {
  const auto f = m.Flux(id, iq, lim.temperature_c);
  return std::hypot(lim.rs_ohm * id - we * f.psi_q_wb, lim.rs_ohm * iq + we * f.psi_d_wb);
}

namespace {

// Least-current point for torque t under the limits; false if infeasible.
// `mtpa_id` (optional): the least-current id of this torque without a
// voltage limit, when already known (it does not depend on speed).
bool TrySolve(const sim::MagneticModel& m, const MachineLimits& lim, double t, double we,
              OperatingPoint* op, const double* mtpa_id = nullptr) {
  *op = OperatingPoint{};
  if (t == 0.0 && we <= 0) return true;
  const double s = t < 0 ? -1.0 : 1.0;
  const double id_min = -lim.i_max_a;
  auto iq_of = [&](double id, double* iq) { return SolveIqForTorque(m, lim, id, t, s, iq); };
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
OperatingPoint SolveWithMax(const sim::MagneticModel& m, const MachineLimits& lim, double t,
                            double we, double tmax, const double* mtpa_id = nullptr) {
  OperatingPoint op;
  if (std::abs(t) <= tmax && TrySolve(m, lim, t, we, &op, mtpa_id)) return op;
  // Infeasible: deliver the largest torque of the same sign within limits.
  const double s = t < 0 ? -1.0 : 1.0;
  double tt = s * tmax;
  for (int k = 0; k < 8 && !TrySolve(m, lim, tt, we, &op); ++k) tt *= 1 - 1e-6 * (1 << (2 * k));
  op.clamped = true;
  return op;
}

}  // namespace

OperatingPoint SolveLeastCurrent(const sim::MagneticModel& m, const MachineLimits& lim, double t,
                                 double we) {
  OperatingPoint op;
  if (TrySolve(m, lim, t, we, &op)) return op;
  return SolveWithMax(m, lim, t, we, MaxTorqueNm(m, lim, we, t < 0 ? -1.0 : 1.0));
}

double MaxTorqueNm(const sim::MagneticModel& m, const MachineLimits& lim, double we,
                   double sign) {
  const double s = sign < 0 ? -1.0 : 1.0;
  // Bisection on the torque request t: feasible if some point of the
  // constant-torque locus lies inside both limits, i.e. if the minimum over
  // the locus of h = max(|i| / i_max, |u| / u_max) is at most 1. |i| and |u|
  // each have a single minimum along the locus (MTPA, MTPV), so h is
  // quasi-convex and the scan + golden section finds its minimum even when
  // the feasible arc is short (near the limit torque at high speed).
  auto feasible = [&](double t) {
    auto h = [&](double id) {
      double iq;
      if (!SolveIqForTorque(m, lim, id, t, s, &iq)) return 1e30;
      const double c = std::hypot(id, iq) / lim.i_max_a;
      return we > 0 ? std::max(c, VoltageV(m, lim, id, iq, we) / lim.UMaxV()) : c;
    };
    return h(MinimiseScalar(h, -lim.i_max_a, 0.0, 24, 40)) <= 1.0;
  };
  double lo = 0.0, hi = 1.0;
  while (feasible(hi) && hi < 1e5) { lo = hi; hi *= 2; }
  // 26 halvings: the limit torque to ~1e-8 of its value.
  for (int k = 0; k < 26; ++k) {
    const double mid = 0.5 * (lo + hi);
    if (feasible(mid)) lo = mid; else hi = mid;
  }
  return lo;
}

absl::StatusOr<Table> BuildTable(const sim::MagneticModel& m, const MachineLimits& lim,
                                 const TableSpec& spec) {
  if (spec.points < 2 || spec.points > 4096) {
    return absl::InvalidArgumentError(absl::StrCat("flag --points: must be 2..4096, got ", spec.points));
  }
  if (!(lim.i_max_a > 0) || !(lim.udc_v > 0)) {
    return absl::InvalidArgumentError("limits: i_max_a and udc_v must be positive");
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
    const auto tq = spec.include_generating ? Linspace(-tmax, tmax, spec.points) : Linspace(0, tmax, spec.points);
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
    const auto lam = Linspace(lmin, lmax, spec.points);
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
    const auto tq = spec.include_generating ? Linspace(-tmax, tmax, spec.points) : Linspace(0, tmax, spec.points);
    const auto n = Linspace(0, spec.speed_max_rpm, spec.speed_points);
    Output id{"id_a", {}}, iq{"iq_a", {}};
    // Limit torque per speed, motoring and generating (they differ at speed:
    // the resistive drop subtracts from the voltage when generating).
    std::vector<double> tlim_motor(n.size()), tlim_gen(n.size());
    for (size_t j = 0; j < n.size(); ++j) {
      const double we = n[j] * lim.pole_pairs * 2 * kPi / 60.0;
      tlim_motor[j] = MaxTorqueNm(m, lim, we, 1.0);
      tlim_gen[j] = spec.include_generating ? MaxTorqueNm(m, lim, we, -1.0) : 0.0;
    }
    for (double x : tq) {
      // The MTPA point of this torque row is the same at every speed.
      OperatingPoint mtpa;
      const bool have_mtpa = TrySolve(m, lim, x, 0.0, &mtpa);
      for (size_t j = 0; j < n.size(); ++j) {
        const double we = n[j] * lim.pole_pairs * 2 * kPi / 60.0;
        const double tlim = x < 0 ? tlim_gen[j] : tlim_motor[j];
        const auto op = SolveWithMax(m, lim, x, we, tlim, have_mtpa ? &mtpa.id_a : nullptr);
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
  // current limit (the disc the identified points cover).
  const auto& idv = t.outputs[0].values;
  const auto& iqv = t.outputs[1].values;
  t.extrapolated.assign(idv.size(), 0);
  if (meas > 0) {
    for (size_t k = 0; k < idv.size(); ++k) t.extrapolated[k] = std::hypot(idv[k], iqv[k]) > meas * (1 + 1e-9);
  }
  Seal(&t);
  return t;
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
  return absl::InvalidArgumentError(
      absl::StrCat("flag --format: expected csv, json, h, cdfx or dcm, got '", name, "'"));
}

namespace {

std::string Num(double v) { return absl::StrFormat("%.17g", v); }

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

std::string Ident(const Table& t, const std::string& name) {
  return absl::AsciiStrToUpper(absl::StrCat("FLUXCAL_", t.kind, "_", name));
}

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

std::string CHeader(const Table& t, CType ct) {
  const std::string g = Ident(t, "TABLE_H_");
  const char* type = ct == CType::kFloat ? "float" : "double";
  std::string s = absl::StrFormat("/* fluxcal %s table. Units: SI (A, N m, rpm, Wb, V, Ohm, degC).\n", t.kind);
  for (const auto& [k, v] : TextFields(t)) s += absl::StrCat(" * ", k, ": ", OneLine(v), "\n");
  s += absl::StrCat(" * calibration_version: ", t.calibration_version, "\n");
  for (const auto& sc : Scalars(t)) {
    if (sc.name == "calibration_version") continue;
    s += absl::StrCat(" * ", sc.name, ": ", Num(sc.value), " ", sc.unit, " (", OneLine(sc.description), ")\n");
  }
  s += absl::StrCat(" * axis order: ", AxisOrder(t), ".\n");
  s += absl::StrCat(" * Value arrays are ", type, "; ", Ident(t, "clamped"), " / ", Ident(t, "extrapolated"),
                    " are 0/1 per cell.\n");
  s += " * payload_crc32 / payload_sha256: over the values as IEEE-754 binary64 (fluxcal docs/tables.md),\n"
       " * not over this file";
  if (ct == CType::kFloat) s += "; the float arrays hold those values rounded to binary32";
  s += ". */\n";
  s += absl::StrFormat("#ifndef %s\n#define %s\n\n#include <stdint.h>\n\n", g, g);
  for (const auto& sc : Scalars(t)) {
    s += absl::StrFormat("#define %s %s\n", Ident(t, sc.name),
                         sc.integer ? absl::StrCat(static_cast<long long>(sc.value)) : CNum(sc.value, ct));
  }
  s += "\n";
  for (const auto& [k, v] : TextFields(t)) {
    s += absl::StrFormat("static const char %s[] = %s;\n", absl::AsciiStrToLower(Ident(t, k)), CString(v));
  }
  s += "\n";
  auto arr = [&](const std::string& name, const std::vector<double>& v, const char* ty, bool flag) {
    s += absl::StrFormat("#define %s_LEN %d\n", Ident(t, name), v.size());
    s += absl::StrFormat("static const %s %s[%d] = {\n", ty, absl::AsciiStrToLower(Ident(t, name)), v.size());
    for (size_t k = 0; k < v.size(); ++k) {
      s += absl::StrCat("  ", flag ? (v[k] != 0 ? "1" : "0") : CNum(v[k], ct), k + 1 < v.size() ? ",\n" : "\n");
    }
    s += "};\n\n";
  };
  for (const auto& a : t.axes) arr(a.name, a.values, type, false);
  for (const auto& o : t.outputs) arr(o.name, o.values, type, false);
  for (const auto& [name, v] : Flags(t)) arr(name, AsDoubles(*v), "uint8_t", true);
  s += absl::StrFormat("static const uint32_t %s = 0x%08xu;\n", absl::AsciiStrToLower(Ident(t, "payload_crc32")), t.crc32);
  s += absl::StrFormat("static const char %s[] = \"%s\";\n\n#endif\n",
                       absl::AsciiStrToLower(Ident(t, "payload_sha256")), t.sha256);
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
    s += absl::StrCat(in, "<SW-INSTANCE>\n", in, "  <SHORT-NAME>", Ident(t, name), "</SHORT-NAME>\n", in,
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
    s += absl::StrFormat("FESTWERT %s\n   LANGNAME \"%s\"\n   EINHEIT_W \"%s\"\n   WERT %s\nEND\n\n", Ident(t, sc.name),
                         absl::StrReplaceAll(OneLine(sc.description), {{"\"", "'"}}), sc.unit, Num(sc.value));
  }
  const bool map = t.axes.size() > 1;
  const size_t n0 = t.axes[0].values.size(), n1 = map ? t.axes[1].values.size() : 1;
  auto block = [&](const std::string& name, const std::string& unit, const std::vector<double>& vals) {
    if (!map) {
      s += absl::StrFormat("KENNLINIE %s %d\n   LANGNAME \"%s over %s\"\n   EINHEIT_X \"%s\"\n   EINHEIT_W \"%s\"\n",
                           Ident(t, name), n0, name, t.axes[0].name, UnitOf(t.axes[0].name), unit);
      line("ST/X", t.axes[0].values);
      line("WERT", vals);
    } else {
      // KENNFELD name nx ny: ST/X the X axis (first axis), then per Y value
      // (second axis) one ST/Y line and the WERT values over X.
      s += absl::StrFormat("KENNFELD %s %d %d\n   LANGNAME \"%s over %s x %s\"\n   EINHEIT_X \"%s\"\n   EINHEIT_Y \"%s\"\n   EINHEIT_W \"%s\"\n",
                           Ident(t, name), n0, n1, name, t.axes[0].name, t.axes[1].name, UnitOf(t.axes[0].name),
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
  std::vector<Scalar> s = {
      {"pole_pairs", static_cast<double>(l.pole_pairs), "-", "pole pairs p of the calibration", true},
      {"rs_ohm", l.rs_ohm, "Ohm", "phase resistance Rs used for the steady-state voltage", false},
      {"psi_pm_wb", t.psi_pm_wb, "Wb", "permanent-magnet flux linkage psi_d(0, 0) of the fitted model", false},
      {"i_max_a", l.i_max_a, "A", "current limit the table was computed for (peak, amplitude-invariant)", false},
      {"udc_v", l.udc_v, "V", "DC-link voltage the table was computed for", false},
      {"modulation_limit", l.modulation_limit, "-", "fraction of the linear SVPWM range used", false},
      {"u_max_v", l.UMaxV(), "V", "voltage limit m Udc / sqrt(3) (peak phase, amplitude-invariant)", false},
      {"temperature_c", l.temperature_c, "degC", "temperature the flux model was evaluated at", false},
  };
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
  return {{"clamped", &t.clamped}, {"extrapolated", &t.extrapolated}};
}

absl::StatusOr<CType> ParseCType(const std::string& name) {
  if (name == "double") return CType::kDouble;
  if (name == "float") return CType::kFloat;
  return absl::InvalidArgumentError(absl::StrCat("flag --ctype: expected float or double, got '", name, "'"));
}

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
  switch (f) {
    case Format::kCsv: e.bytes = Csv(t); break;
    case Format::kJson: e.bytes = Json(t); break;
    case Format::kCHeader: e.bytes = CHeader(t, opt.ctype); break;
    case Format::kCdfx: e.bytes = Cdfx(t); break;
    case Format::kDcm: e.bytes = Dcm(t); break;
  }
  e.payload_crc32 = t.crc32;
  e.payload_sha256 = t.sha256;
  e.file_sha256 = io::Sha256Hex(e.bytes);
  return e;
}

std::string PlotCurvesSvg(const sim::MagneticModel& m, const MachineLimits& lim, const Table& mtpa,
                          const Table* mtpv) {
  const double W = 640, H = 480, x0 = 60, y0 = 20, pw = 560, ph = 420;
  const double id_min = -lim.i_max_a, id_max = 0.1 * lim.i_max_a, iq_min = 0, iq_max = 1.1 * lim.i_max_a;
  auto X = [&](double id) { return x0 + (id - id_min) / (id_max - id_min) * pw; };
  auto Y = [&](double iq) { return y0 + ph - (iq - iq_min) / (iq_max - iq_min) * ph; };
  std::string s = absl::StrFormat("<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"%g\" height=\"%g\" font-family=\"sans-serif\" font-size=\"11\">\n", W, H);
  // Curves are clipped to the frame (MTPV runs on beyond -i_max).
  s += absl::StrFormat("<defs><clipPath id=\"frame\"><rect x=\"%g\" y=\"%g\" width=\"%g\" height=\"%g\"/></clipPath></defs>\n",
                       x0, y0, pw, ph);
  s += absl::StrFormat("<rect x=\"%g\" y=\"%g\" width=\"%g\" height=\"%g\" fill=\"white\" stroke=\"black\"/>\n", x0, y0, pw, ph);
  s += absl::StrFormat("<text x=\"%g\" y=\"%g\">id [A]</text>"
                       "<text x=\"12\" y=\"%g\" transform=\"rotate(-90 12 %g)\" text-anchor=\"middle\">iq [A]</text>\n",
                       x0 + pw / 2, H - 5, y0 + ph / 2, y0 + ph / 2);
  for (int k = 0; k <= 4; ++k) {
    const double id = id_min + (id_max - id_min) * k / 4, iq = iq_min + (iq_max - iq_min) * k / 4;
    s += absl::StrFormat("<text x=\"%g\" y=\"%g\">%.0f</text><text x=\"20\" y=\"%g\">%.0f</text>\n", X(id) - 10, y0 + ph + 14, id, Y(iq) + 4, iq);
  }
  // Torque contours: constant-torque loci solved directly.
  const double tmax = MaxTorqueNm(m, lim, 0);
  for (int c = 1; c <= 6; ++c) {
    const double t = tmax * c / 6;
    std::string pts;
    double lx = -1, ly = -1;   // the contour's last point inside the frame: its label goes there
    for (int k = 0; k <= 60; ++k) {
      const double id = id_min + (0 - id_min) * k / 60;
      double iq;
      if (SolveIqForTorque(m, lim, id, t, 1.0, &iq) && iq <= iq_max) {
        pts += absl::StrFormat("%.1f,%.1f ", X(id), Y(iq));
        lx = X(id);
        ly = Y(iq);
      }
    }
    s += absl::StrFormat("<polyline points=\"%s\" fill=\"none\" stroke=\"#999\" clip-path=\"url(#frame)\"/>\n", pts);
    if (lx >= 0) {
      s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" fill=\"#666\" text-anchor=\"end\">%.1f N m</text>\n", lx - 3,
                           ly - 4, t);
    }
  }
  std::string circ;
  for (int k = 0; k <= 90; ++k) {
    const double a = kPi / 2 * k / 90;
    circ += absl::StrFormat("%.1f,%.1f ", X(-lim.i_max_a * std::sin(a)), Y(lim.i_max_a * std::cos(a)));
  }
  s += absl::StrFormat("<polyline points=\"%s\" fill=\"none\" stroke=\"black\" stroke-dasharray=\"4 3\"/>\n", circ);
  auto curve = [&](const Table& t, const char* color, const char* label) {
    std::string pts;
    const auto& id = t.outputs[0].values;
    const auto& iq = t.outputs[1].values;
    for (size_t k = 0; k < id.size(); ++k)
      if (iq[k] >= 0) pts += absl::StrFormat("%.1f,%.1f ", X(id[k]), Y(iq[k]));
    s += absl::StrFormat("<polyline points=\"%s\" fill=\"none\" stroke=\"%s\" stroke-width=\"2\" clip-path=\"url(#frame)\"/>\n",
                         pts, color);
    s += absl::StrFormat("<text x=\"%g\" y=\"%g\" fill=\"%s\">%s</text>\n", x0 + 10, y0 + ph - (label[1] == 'T' && label[3] == 'V' ? 30 : 15), color, label);
  };
  curve(mtpa, "#c00", "MTPA");
  if (mtpv) curve(*mtpv, "#00c", "MTPV");
  s += "</svg>\n";
  return s;
}

std::string PlotMapSvg(const Table& fw, const std::string& output_name) {
  const Output* o = nullptr;
  for (const auto& out : fw.outputs) if (out.name == output_name) o = &out;
  if (o == nullptr || fw.axes.size() != 2) return "";
  const size_t n0 = fw.axes[0].values.size(), n1 = fw.axes[1].values.size();
  const double x0 = 70, y0 = 30, pw = 540, ph = 400;
  double lo = *std::min_element(o->values.begin(), o->values.end());
  double hi = *std::max_element(o->values.begin(), o->values.end());
  if (hi <= lo) hi = lo + 1;
  auto colour = [&](double v) {
    const double u = std::clamp((v - lo) / (hi - lo), 0.0, 1.0);
    return absl::StrFormat("rgb(%d,60,%d)", static_cast<int>(255 * u), static_cast<int>(255 * (1 - u)));
  };
  std::string s = absl::StrFormat(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"760\" height=\"500\" font-family=\"sans-serif\" "
      "font-size=\"11\">\n<text x=\"%g\" y=\"18\" font-size=\"13\">%s [%s] over torque request and speed%s</text>\n",
      x0, output_name, UnitOf(output_name), fw.serial.empty() ? "" : " (" + fw.serial + ")");
  const double cw = pw / n1, ch = ph / n0;
  for (size_t i = 0; i < n0; ++i) {
    for (size_t j = 0; j < n1; ++j) {
      s += absl::StrFormat("<rect class=\"cell\" x=\"%.2f\" y=\"%.2f\" width=\"%.2f\" height=\"%.2f\" fill=\"%s\"/>\n",
                           x0 + j * cw, y0 + ph - (i + 1) * ch, cw + 0.3, ch + 0.3, colour(o->values[i * n1 + j]));
    }
  }
  // Axes: five ticks each, at cell centres.
  for (int k = 0; k <= 4; ++k) {
    const size_t j = (n1 - 1) * k / 4, i = (n0 - 1) * k / 4;
    s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%.0f</text>\n", x0 + (j + 0.5) * cw,
                         y0 + ph + 14, fw.axes[1].values[j]);
    s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\">%.1f</text>\n", x0 - 4,
                         y0 + ph - (i + 0.5) * ch + 4, fw.axes[0].values[i]);
  }
  s += absl::StrFormat("<text x=\"%g\" y=\"%g\" text-anchor=\"middle\">speed [rpm]</text>\n", x0 + pw / 2, y0 + ph + 32);
  s += absl::StrFormat("<text x=\"14\" y=\"%g\" transform=\"rotate(-90 14 %g)\" text-anchor=\"middle\">torque [N m]</text>\n",
                       y0 + ph / 2, y0 + ph / 2);
  // Colour bar.
  const double bx = x0 + pw + 30, bw = 18;
  for (int k = 0; k < 50; ++k) {
    const double v = lo + (hi - lo) * (k + 0.5) / 50;
    s += absl::StrFormat("<rect class=\"scale\" x=\"%.1f\" y=\"%.2f\" width=\"%.1f\" height=\"%.2f\" fill=\"%s\"/>\n", bx,
                         y0 + ph - (k + 1) * ph / 50, bw, ph / 50 + 0.3, colour(v));
  }
  s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\">%.1f</text><text x=\"%.1f\" y=\"%.1f\">%.1f</text>\n", bx + bw + 4,
                       y0 + 10, hi, bx + bw + 4, y0 + ph, lo);
  s += "</svg>\n";
  return s;
}

}  // namespace fluxcal::tables
