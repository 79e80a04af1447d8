#include "tables/flux_map_export.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "fitting/flux_error.h"

namespace fluxcal::tables {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr int kDefaultNodes = 21;

absl::Status CheckAxis(const LinearAxis& a, const char* field) {
  if (a.n < 1 || a.n > kMaxFluxMapAxisNodes) {
    return absl::InvalidArgumentError(absl::StrCat("field '", field, "': node count must be 1..",
                                                   kMaxFluxMapAxisNodes, ", got ", a.n));
  }
  if (!std::isfinite(a.min) || !std::isfinite(a.max)) {
    return absl::InvalidArgumentError(absl::StrCat("field '", field, "': bounds must be finite"));
  }
  if (a.n > 1 && !(a.max > a.min)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "field '%s': max must exceed min for %d nodes, got %g:%g", field, a.n, a.min, a.max));
  }
  return absl::OkStatus();
}

// The box the inverse solve stays in: the measured id range and the measured
// |iq| range on both sides of iq = 0 (every model family is odd in iq,
// fitting/flux_family.h, and the region is mirrored likewise), without the
// 2 % margin InMeasuredRegion allows; a solution in the strip
// |iq| < iq_min_a (when the data started above iq = 0) is rejected.
struct Box {
  double id_lo, id_hi, iq_lo, iq_hi;
  double ClampId(double x) const { return std::clamp(x, id_lo, id_hi); }
  double ClampIq(double x) const { return std::clamp(x, iq_lo, iq_hi); }
};

Box SolveBox(const fit::Calibration& cal) {
  return {cal.id_min_a(), cal.id_max_a(), cal.iq_min_a() >= 0 ? -cal.iq_max_a() : cal.iq_min_a(), cal.iq_max_a()};
}

// Damped Newton for F(i) = psi* with F the calibration's flux linkage.
//
// Newton's step for a system of equations (Nocedal & Wright, Numerical
// Optimization, 2nd ed., ch. 11) solves J(i) d = psi* - F(i) with J the
// Jacobian of flux with respect to current, which is the differential
// inductance (simulation/magnetic_model.h):
//   J = [[Ldd, Ldq], [Ldq, Lqq]],  d = J^-1 (psi* - F(i))   (2 x 2, Cramer).
// Every family is a co-energy gradient, psi = grad W'(i), so J is symmetric,
// and Fit only accepts surfaces with J positive definite over the measured
// region (Calibration::PhysicalOver). There W' is strictly convex and F is
// strictly monotone, (F(a) - F(b)).(a - b) > 0 for a != b, so F(a) = F(b)
// forces a = b: the inverse, where it exists in the (convex) box, is
// unique, and any start that converges finds it. The one exception: the
// cells around a point the bench measured non-positive are exempt from
// the check (fitting/screen.cc, Screen), as the machine's map falls
// there; a flux that such a map reaches twice has no single current, and
// the iteration below stops where J is not positive definite, so a node is solved only
// if it converges before, and is marked invalid otherwise. The step is a descent
// direction of the merit function m = |F(i) - psi*|^2 / 2 (dm/dalpha =
// r^T J d = -|r|^2 < 0 at alpha = 0), so backtracking (alpha = 1, 1/2, ...;
// accept on sufficient decrease of |r|, Armijo with c = 1e-4) always
// makes progress while J stays positive definite. Iterates are projected
// onto the box: a target whose solution lies outside it stalls on the box
// boundary with |r| > tolerance and is reported invalid, instead of walking
// into the calibration's extrapolation.
bool SolveNode(const fit::Calibration& cal, const Box& box, double psi_d, double psi_q, double id0, double iq0,
               const InverseFluxMapOptions& o, double* id_out, double* iq_out) {
  double id = box.ClampId(id0), iq = box.ClampIq(iq0);
  auto residual = [&](double a, double b, double* rd, double* rq) {
    const auto f = cal.Flux(a, b);
    *rd = f.psi_d_wb - psi_d;
    *rq = f.psi_q_wb - psi_q;
    return std::hypot(*rd, *rq);
  };
  double rd, rq;
  double nr = residual(id, iq, &rd, &rq);
  for (int it = 0; it < o.max_iterations && nr > 1e-3 * o.tolerance_wb; ++it) {
    const auto L = cal.Inductance(id, iq);
    const double det = L.ldd_h * L.lqq_h - L.ldq_h * L.ldq_h;
    if (!(L.ldd_h > 0) || !(det > 0)) break;   // not positive definite: no descent guarantee
    const double dd = -(L.lqq_h * rd - L.ldq_h * rq) / det;
    const double dq = -(L.ldd_h * rq - L.ldq_h * rd) / det;
    bool accepted = false;
    double nid = id, niq = iq, nrd = rd, nrq = rq, nnr = nr;
    for (double alpha = 1.0; alpha >= 1.0 / 16384; alpha *= 0.5) {
      nid = box.ClampId(id + alpha * dd);
      niq = box.ClampIq(iq + alpha * dq);
      nnr = residual(nid, niq, &nrd, &nrq);
      if (nnr <= (1.0 - 1e-4 * alpha) * nr) {
        accepted = true;
        break;
      }
    }
    if (!accepted) break;   // stalled (on the box boundary, or at rounding level)
    const double step = std::hypot(nid - id, niq - iq);
    id = nid; iq = niq; rd = nrd; rq = nrq; nr = nnr;
    if (step <= 1e-15 * (1.0 + std::hypot(id, iq))) break;
  }
  *id_out = id;
  *iq_out = iq;
  const bool in_strip = cal.iq_min_a() > 0 && std::abs(iq) < cal.iq_min_a();
  return nr <= o.tolerance_wb && !in_strip;
}

}  // namespace

std::vector<double> LinearAxis::Values() const {
  std::vector<double> v(std::max(n, 0));
  for (int k = 0; k < n; ++k) {
    // Ends exact (k = n - 1 gives max, not min + (max - min)); + 0.0 turns
    // -0 into 0.
    v[k] = (n == 1 ? min : (k == n - 1 ? max : min + (max - min) * k / (n - 1))) + 0.0;
  }
  return v;
}

CurrentRegion MeasuredRegion(const fit::Calibration& cal) {
  return {cal.id_min_a(), cal.id_max_a(), cal.iq_min_a(), cal.iq_max_a()};
}

void DefaultCurrentGrid(const fit::Calibration& cal, LinearAxis* id, LinearAxis* iq) {
  const auto r = MeasuredRegion(cal);
  *id = {r.id_min_a, r.id_max_a, r.id_max_a > r.id_min_a ? kDefaultNodes : 1};
  *iq = {r.iq_min_a, r.iq_max_a, r.iq_max_a > r.iq_min_a ? kDefaultNodes : 1};
}

absl::StatusOr<io::FluxMap> SampleFluxMap(const sim::MagneticModel& model, const LinearAxis& id,
                                          const LinearAxis& iq) {
  if (auto st = CheckAxis(id, "grid id"); !st.ok()) return st;
  if (auto st = CheckAxis(iq, "grid iq"); !st.ok()) return st;
  io::FluxMap map;
  map.id_a = id.Values();
  map.iq_a = iq.Values();
  map.psi_d_wb.assign(map.id_a.size(), std::vector<double>(map.iq_a.size()));
  map.psi_q_wb = map.psi_d_wb;
  for (size_t i = 0; i < map.id_a.size(); ++i) {
    for (size_t j = 0; j < map.iq_a.size(); ++j) {
      const auto f = model.Flux(map.id_a[i], map.iq_a[j]);
      map.psi_d_wb[i][j] = f.psi_d_wb;
      map.psi_q_wb[i][j] = f.psi_q_wb;
    }
  }
  if (auto st = io::ValidateFluxMap(map); !st.ok()) {
    return absl::InvalidArgumentError(absl::StrCat("the model's flux is not finite on the grid: ", st.message()));
  }
  return map;
}

absl::StatusOr<CalibrationFluxMap> SampleCalibration(const fit::Calibration& cal, const LinearAxis& id,
                                                     const LinearAxis& iq) {
  auto map = SampleFluxMap(cal, id, iq);
  if (!map.ok()) return map.status();
  CalibrationFluxMap out;
  out.map = std::move(*map);
  for (double a : out.map.id_a)
    for (double b : out.map.iq_a) out.extrapolated += cal.InMeasuredRegion(a, b) ? 0 : 1;
  return out;
}

void DefaultFluxGrid(const fit::Calibration& cal, LinearAxis* psi_d, LinearAxis* psi_q) {
  LinearAxis id, iq;
  DefaultCurrentGrid(cal, &id, &iq);
  double d_lo = std::numeric_limits<double>::infinity(), d_hi = -d_lo, q_lo = d_lo, q_hi = -d_lo;
  for (double a : id.Values()) {
    for (double b : iq.Values()) {
      const auto f = cal.Flux(a, b);
      d_lo = std::min(d_lo, f.psi_d_wb); d_hi = std::max(d_hi, f.psi_d_wb);
      q_lo = std::min(q_lo, f.psi_q_wb); q_hi = std::max(q_hi, f.psi_q_wb);
    }
  }
  *psi_d = {d_lo, d_hi, d_hi > d_lo ? kDefaultNodes : 1};
  *psi_q = {q_lo, q_hi, q_hi > q_lo ? kDefaultNodes : 1};
}

absl::StatusOr<InverseFluxMap> InvertCalibration(const fit::Calibration& cal, const LinearAxis& psi_d,
                                                 const LinearAxis& psi_q, const InverseFluxMapOptions& o) {
  if (auto st = CheckAxis(psi_d, "psi grid psi_d"); !st.ok()) return st;
  if (auto st = CheckAxis(psi_q, "psi grid psi_q"); !st.ok()) return st;
  InverseFluxMap inv;
  inv.psi_d_wb = psi_d.Values();
  inv.psi_q_wb = psi_q.Values();
  const size_t nd = inv.psi_d_wb.size(), nq = inv.psi_q_wb.size();
  inv.id_a.assign(nd, std::vector<double>(nq, kNaN));
  inv.iq_a = inv.id_a;
  inv.valid.assign(nd, std::vector<uint8_t>(nq, 0));
  const Box box = SolveBox(cal);
  // Cold starts: the centre of the box and the current nearest to zero in
  // it (psi_pm's node when the box holds it).
  const double cold[2][2] = {{0.5 * (box.id_lo + box.id_hi), 0.5 * (box.iq_lo + box.iq_hi)},
                             {box.ClampId(0.0), box.ClampIq(0.0)}};
  for (size_t i = 0; i < nd; ++i) {
    for (size_t j = 0; j < nq; ++j) {
      // Warm starts from solved neighbours (the previous node of this row,
      // the same node of the previous row): a neighbouring flux is a
      // neighbouring current, so Newton starts within a few steps of the
      // answer, in its region of quadratic convergence.
      std::vector<std::pair<double, double>> starts;
      if (j > 0 && inv.valid[i][j - 1]) starts.push_back({inv.id_a[i][j - 1], inv.iq_a[i][j - 1]});
      if (i > 0 && inv.valid[i - 1][j]) starts.push_back({inv.id_a[i - 1][j], inv.iq_a[i - 1][j]});
      for (const auto& c : cold) starts.push_back({c[0], c[1]});
      for (const auto& [a, b] : starts) {
        double id, iq;
        if (SolveNode(cal, box, inv.psi_d_wb[i], inv.psi_q_wb[j], a, b, o, &id, &iq)) {
          inv.id_a[i][j] = id;
          inv.iq_a[i][j] = iq;
          inv.valid[i][j] = 1;
          ++inv.valid_nodes;
          break;
        }
      }
    }
  }
  return inv;
}

std::string InverseFluxMapCsv(const InverseFluxMap& inv) {
  std::string out = "psi_d_Vs,psi_q_Vs,id_A,iq_A,valid\n";
  for (size_t i = 0; i < inv.psi_d_wb.size(); ++i) {
    for (size_t j = 0; j < inv.psi_q_wb.size(); ++j) {
      if (inv.valid[i][j]) {
        absl::StrAppendFormat(&out, "%.17g,%.17g,%.17g,%.17g,1\n", inv.psi_d_wb[i], inv.psi_q_wb[j],
                              inv.id_a[i][j], inv.iq_a[i][j]);
      } else {
        absl::StrAppendFormat(&out, "%.17g,%.17g,,,0\n", inv.psi_d_wb[i], inv.psi_q_wb[j]);
      }
    }
  }
  return out;
}

absl::StatusOr<FluxMapComparison> CompareWithFluxMap(const sim::MagneticModel& model, const io::FluxMap& map,
                                                     const CurrentRegion& region) {
  FluxMapComparison c;
  c.region = region;
  std::vector<io::FluxMapPoint> inside;
  for (const auto& p : map.Points()) {
    if (region.Contains(p.id_a, p.iq_a)) inside.push_back(p);
  }
  if (inside.empty()) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: field 'region': no node of the map lies in id %g..%g A, iq %g..%g A (map: id %g..%g A, iq %g..%g A)",
        map.source.empty() ? "flux map" : map.source, region.id_min_a, region.id_max_a, region.iq_min_a,
        region.iq_max_a, map.id_a.empty() ? 0.0 : map.id_a.front(), map.id_a.empty() ? 0.0 : map.id_a.back(),
        map.iq_a.empty() ? 0.0 : map.iq_a.front(), map.iq_a.empty() ? 0.0 : map.iq_a.back()));
  }
  // The error itself is computed where a map fit's summary computes it.
  const fit::FluxNodeError e = fit::FluxErrorOverNodes(model, inside);
  c.nodes = e.nodes;
  c.psi_scale_wb = e.psi_scale_wb;
  c.rms_wb = e.rms_wb;
  c.max_wb = e.max_wb;
  c.rms_relative = e.rms_relative;
  c.max_relative = e.max_relative;
  c.rms_d_wb = e.rms_d_wb;
  c.rms_q_wb = e.rms_q_wb;
  c.worst = inside[e.worst];
  c.worst_error_d_wb = e.worst_error_d_wb;
  c.worst_error_q_wb = e.worst_error_q_wb;
  return c;
}

}  // namespace fluxcal::tables
