// BuildTable (tables/tables.h) in its steps: the request checked, the
// table's provenance, the rows of its kind (MTPA, MTPV, field weakening)
// from the operating-point solver (solver.cc), each cell's flags; and the
// round breakpoints of its axes.
#include <algorithm>
#include <cmath>
#include <ctime>
#include <numbers>
#include <optional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "fitting/calibration.h"
#include "physics/speed.h"
#include "physics/torque.h"
#include "tables/internal_numeric.h"
#include "tables/internal_solver.h"
#include "tables/tables.h"

namespace fluxcal::tables {
namespace {

using internal::LimitTorque;
using internal::LimitTorques;
using internal::Linspace;
using internal::MinimiseScalar;
using internal::MtpaNewton;
using internal::RowLoci;
using internal::SolveWithMax;
using internal::TrySolve;

constexpr double kPi = std::numbers::pi;

std::string NowUtc() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", std::gmtime(&t));
  return buf;
}

// The errors of BuildTable that the request alone decides (tables.h): the
// points, pole pairs, limits, the fw map's voltage limit, a current limit
// above the measured one.
absl::Status CheckRequest(const MachineLimits& lim, const TableSpec& spec) {
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
  if ((spec.kind == "fw" || spec.kind == "envelope") && !lim.HasVoltageLimit()) {
    // u = Rs i + w J psi against m Udc / sqrt(3): neither may be assumed.
    return absl::InvalidArgumentError(absl::StrCat(
        "table ", spec.kind, ": the ", spec.kind == "fw" ? "field-weakening map" : "torque-speed envelope",
        " needs the voltage limit: ",
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
  return absl::OkStatus();
}

// A table of spec.kind with its provenance and the limits it is computed
// for; no rows yet.
Table NewTable(const sim::MagneticModel& m, const MachineLimits& lim, const TableSpec& spec) {
  const double meas = spec.measured_current_limit_a;
  Table t;
  t.kind = spec.kind;
  t.envelope_generating = spec.kind == "envelope" && spec.envelope_generating;
  // The generating envelope's labels differ from the motoring one's
  // (FLUXCAL_ENVELOPE_GENERATING_...): both can be flashed side by side.
  t.label_tag = t.envelope_generating
                    ? absl::StrCat(kGeneratingTag, spec.label_tag.empty() ? "" : "_", spec.label_tag)
                    : spec.label_tag;
  t.magnet_temperature = spec.magnet_temperature;
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
  t.speed_max_rpm = spec.kind == "fw" || spec.kind == "envelope" ? spec.speed_max_rpm : 0.0;
  t.measured_current_limit_a = meas > 0 ? meas : 0.0;
  t.allow_extrapolation = spec.allow_extrapolation;
  return t;
}

// MTPA: the least-current point of each round torque request up to the
// limit torque at standstill `tmax`.
absl::Status MtpaRows(const sim::MagneticModel& m, const MachineLimits& lim, const TableSpec& spec, double tmax,
                      Table* out) {
  Table& t = *out;
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
  return absl::OkStatus();
}

// MTPV: the torque-maximising point of each round flux magnitude.
absl::Status MtpvRows(const sim::MagneticModel& m, const MachineLimits& lim, const TableSpec& spec, Table* out) {
  Table& t = *out;
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
  return absl::OkStatus();
}

// Field weakening: the least-current point under both limits over round
// torque requests (up to the limit torque at standstill, `still`: its t) x
// round speeds.
absl::Status FwRows(const sim::MagneticModel& m, const MachineLimits& lim, const TableSpec& spec,
                    const LimitTorque& still, Table* out) {
  const double tmax = still.t;
  Table& t = *out;
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
  // The fast solves (RowLoci, LimitTorques) only within the measured current
  // limit: beyond it (--i-max-a above it with --allow-extrapolation) the
  // extrapolated surface breaks the premises their checks rest on (torque
  // monotone in iq, one voltage minimum along a locus): a locus may cross
  // the voltage limit several times, and the robust solve's choice among
  // those crossings is kept there.
  const double meas = spec.measured_current_limit_a;
  const bool fast = !(meas > 0) || lim.i_max_a <= meas * (1 + 1e-9);
  std::vector<double> we_axis(n.size());
  for (size_t j = 0; j < n.size(); ++j) we_axis[j] = physics::RpmToElectricalRadS(n[j], lim.pole_pairs);
  const std::vector<LimitTorque> tlim_motor = LimitTorques(m, lim, we_axis, 1.0, fast, &still);
  const std::vector<LimitTorque> tlim_gen =
      spec.include_generating ? LimitTorques(m, lim, we_axis, -1.0, fast) : std::vector<LimitTorque>(n.size());
  // The clamped point per speed and torque sign (SolveWithMax).
  std::vector<std::optional<OperatingPoint>> clamp_motor(n.size()), clamp_gen(n.size());
  // The previous row's MTPA point, the start of the next row's MtpaNewton.
  OperatingPoint mtpa_prev;
  bool have_prev = false;
  for (double x : tq) {
    // The MTPA point of this torque row is the same at every speed. Fast
    // (MtpaNewton) from the previous row's of the same sign, checked;
    // otherwise, near the current limit (TrySolve's test there, as for a
    // cell: CurrentLimitSettled) and for the first row of each sign the
    // robust solve.
    OperatingPoint mtpa;
    bool have_mtpa = false, solved = false;
    double id_f, iq_f;
    if (fast && x != 0.0 && have_prev && mtpa_prev.iq_a * x > 0 &&
        MtpaNewton(m, lim, x, x < 0 ? -1.0 : 1.0, mtpa_prev.id_a, mtpa_prev.iq_a, &id_f, &iq_f) &&
        std::abs(std::hypot(id_f, iq_f) - lim.i_max_a * (1 + 1e-9)) > 1e-8) {
      solved = true;
      have_mtpa = std::hypot(id_f, iq_f) <= lim.i_max_a * (1 + 1e-9);
      if (have_mtpa) mtpa = OperatingPoint{id_f, iq_f, TorqueNm(m, lim.pole_pairs, id_f, iq_f, lim.temperature_c)};
    }
    if (!solved) have_mtpa = TrySolve(m, lim, x, 0.0, &mtpa);
    have_prev = have_mtpa;
    mtpa_prev = mtpa;
    // The row's cells move little from one speed to the next: each
    // voltage-limited one starts the next speed's fast solve (RowLoci).
    RowLoci row;
    row.fast = fast;
    for (size_t j = 0; j < n.size(); ++j) {
      const LimitTorque& tlim = x < 0 ? tlim_gen[j] : tlim_motor[j];
      const auto op = SolveWithMax(m, lim, x, we_axis[j], tlim.t, have_mtpa ? &mtpa.id_a : nullptr,
                                   x < 0 ? &clamp_gen[j] : &clamp_motor[j], &row, &tlim);
      id.values.push_back(op.id_a);
      iq.values.push_back(op.iq_a);
      t.clamped.push_back(op.clamped);
    }
  }
  t.axes = {{"torque_nm", tq}, {"speed_rpm", n}};
  t.outputs = {id, iq};
  return absl::OkStatus();
}

// The envelope: per round speed, the largest motoring torque inside both
// limits (MaxTorqueNm) and its operating point, the least-current point of
// that torque under the limits (SolveWithMax with the limit as its
// maximum: the MTPA point below base speed, on the voltage limit above).
absl::Status EnvelopeRows(const sim::MagneticModel& m, const MachineLimits& lim, const TableSpec& spec,
                          Table* out) {
  Table& t = *out;
  if (!(spec.speed_max_rpm > 0) || !std::isfinite(spec.speed_max_rpm)) {
    return absl::InvalidArgumentError("flag --speed-max-rpm: must be positive");
  }
  auto n_axis = RoundBreakpoints(0.0, spec.speed_max_rpm, spec.speed_points, "--speed-points");
  if (!n_axis.ok()) return n_axis.status();
  const auto& n = *n_axis;
  t.speed_max_rpm = n.back();
  Output id{"id_a", {}}, iq{"iq_a", {}}, tq{"torque_nm", {}}, pw{"power_w", {}};
  const double sign = spec.envelope_generating ? -1.0 : 1.0;
  for (double rpm : n) {
    const double we = physics::RpmToElectricalRadS(rpm, lim.pole_pairs);
    const double tlim = MaxTorqueNm(m, lim, we, sign);
    OperatingPoint op;
    bool none = !(tlim > 0);
    if (!none) {
      op = SolveWithMax(m, lim, sign * tlim, we, tlim);
      none = !(sign * op.torque_nm > 0);
    }
    if (none) op = OperatingPoint{};
    id.values.push_back(op.id_a);
    iq.values.push_back(op.iq_a);
    // The torque the point delivers (within 1e-9 of the limit torque).
    tq.values.push_back(op.torque_nm);
    // (+ 0.0: the generating power at standstill is 0, not -0.)
    pw.values.push_back(op.torque_nm * rpm * 2 * kPi / 60.0 + 0.0);
    t.clamped.push_back(none);
  }
  t.axes = {{"speed_rpm", n}};
  t.outputs = {id, iq, tq, pw};
  return absl::OkStatus();
}

// Each cell's flags. Extrapolated: the operating point of the cell lies
// beyond the measured current limit `meas` (the disc the identified points
// cover), or outside a calibration's measured region and its mirror image.
// By symmetry: on the mirror image only (a generating row of a
// motoring-only bench, from a model symmetric in iq). Not positive
// definite: the model's differential inductance there fails Sylvester's
// test (one test for the fit, queries and tables:
// fit::NotPositiveDefiniteReason).
void FlagCells(const sim::MagneticModel& m, const MachineLimits& lim, double meas, Table* out) {
  Table& t = *out;
  const auto& idv = t.outputs[0].values;
  const auto& iqv = t.outputs[1].values;
  // A table at another magnet temperature keeps its calibration's regions.
  const auto* scaled = dynamic_cast<const MagnetScaledModel*>(&m);
  const auto* cal = dynamic_cast<const fit::Calibration*>(scaled != nullptr ? &scaled->base() : &m);
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
}

}  // namespace

MagnetScaledModel::MagnetScaledModel(const sim::MagneticModel& base, const MagnetTemperature& t)
    : base_(base), t_(t) {}

sim::FluxLinkage MagnetScaledModel::Flux(double id, double iq, double temperature_c) const {
  sim::FluxLinkage f = base_.Flux(id, iq, temperature_c);
  f.psi_d_wb += (t_.Scale() - 1.0) * base_.Flux(0.0, 0.0, temperature_c).psi_d_wb;
  return f;
}

sim::DifferentialInductance MagnetScaledModel::Inductance(double id, double iq, double temperature_c) const {
  return base_.Inductance(id, iq, temperature_c);
}

void MagnetScaledModel::FluxAndInductance(double id, double iq, double temperature_c, sim::FluxLinkage* flux,
                                          sim::DifferentialInductance* inductance) const {
  base_.FluxAndInductance(id, iq, temperature_c, flux, inductance);
  flux->psi_d_wb += (t_.Scale() - 1.0) * base_.Flux(0.0, 0.0, temperature_c).psi_d_wb;
}

std::string UdcTag(double udc_v) {
  std::string s = absl::StrFormat("%.6g", udc_v);
  for (auto& c : s) c = c == '.' ? 'p' : c;
  return absl::StrCat("udc", s, "v");
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

absl::StatusOr<Table> BuildTable(const sim::MagneticModel& m_in, const MachineLimits& lim,
                                 const TableSpec& spec) {
  if (absl::Status st = CheckRequest(lim, spec); !st.ok()) return st;
  std::optional<MagnetScaledModel> scaled;
  if (spec.magnet_temperature) {
    const MagnetTemperature& mt = *spec.magnet_temperature;
    if (!std::isfinite(mt.alpha_per_k) || !std::isfinite(mt.at_c) || !std::isfinite(mt.reference_c) ||
        !(mt.Scale() > 0)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "flag --magnet-temp-c: %.6g degC with the coefficient %.6g /K from %.6g degC gives no positive magnet flux",
          mt.at_c, mt.alpha_per_k, mt.reference_c));
    }
    scaled.emplace(m_in, mt);
  }
  const sim::MagneticModel& m = scaled ? *scaled : m_in;
  const double meas = spec.measured_current_limit_a;
  Table t = NewTable(m, lim, spec);
  // The limit torque at standstill (MaxTorqueNm), with its point: the fw
  // table's limit below base speed too (computed once).
  const LimitTorque still = internal::LimitTorqueAt(m, lim, 0.0, 1.0);
  const double tmax = still.t;
  absl::Status rows;
  if (spec.kind == "mtpa") {
    rows = MtpaRows(m, lim, spec, tmax, &t);
  } else if (spec.kind == "mtpv") {
    rows = MtpvRows(m, lim, spec, &t);
  } else if (spec.kind == "fw") {
    rows = FwRows(m, lim, spec, still, &t);
  } else if (spec.kind == "envelope") {
    rows = EnvelopeRows(m, lim, spec, &t);
  } else {
    return absl::InvalidArgumentError(
        absl::StrCat("flag --table: expected mtpa, mtpv, fw or envelope, got '", spec.kind, "'"));
  }
  if (!rows.ok()) return rows;
  FlagCells(m, lim, meas, &t);
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
  } else if (t.kind == "envelope" && t.axes.size() == 1) {
    const auto& n = t.axes[0].values;
    size_t first = n.size();
    for (size_t k = 0; k < t.clamped.size(); ++k) {
      if (t.clamped[k]) first = std::min(first, k);
    }
    c.why = absl::StrFormat(
        "no torque is available from %.0f rpm on: the voltage limit u_max %.4g V (Udc %.4g V, Rs %.4g ohm) is "
        "reached at zero torque (%zu of %zu speeds up to %.0f rpm; current limit %.4g A)",
        n[first], l.UMaxV(), l.udc_v.value_or(0.0), l.rs_ohm.value_or(0.0), n.size() - first, n.size(), n.back(),
        l.i_max_a);
  } else if (t.kind == "mtpv") {
    c.why = absl::StrFormat("the MTPV points of those fluxes lie beyond the current limit %.4g A", l.i_max_a);
  } else {
    c.why = absl::StrFormat("the torque requested exceeds the limit torque at the current limit %.4g A", l.i_max_a);
  }
  return c;
}

}  // namespace fluxcal::tables
