#include "diagnosis/internal.h"

#include <algorithm>
#include <cmath>
#include <functional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace fluxcal::diag::detail {

// Per-observation normalised residuals (per real component) for locating.

std::vector<Z> Residuals(const Model& m, const Params& p) {
  const auto ptr = p.Ptrs();
  std::vector<Z> out;
  for (const auto& o : m.hf) {
    Complex i0, i1;
    m.PredictHf(ptr.data(), o, &i0, &i1);
    out.push_back({o.point, "hf_current", o.id_a, o.iq_a, o.speed_rpm,
                   std::norm((o.i0 - i0) / o.sigma0) + std::norm((o.i1 - i1) / o.sigma1), 4});
  }
  for (const auto& o : m.dc) {
    out.push_back({o.point, "dc_voltage", o.id_a, o.iq_a, 0.0, std::norm((o.u - m.PredictDc(ptr.data(), o)) / o.sigma), 2});
  }
  for (size_t k = 0; k < m.ss.size(); ++k) {
    const auto& o = m.ss[k];
    const std::string id = absl::StrFormat("steady_state[%d]", k);
    out.push_back({id, "steady_state_voltage", o.id_a, o.iq_a, o.speed_rpm,
                   std::norm((o.u - m.PredictSs(ptr.data(), o)) / o.sigma), 2});
    if (o.has_torque) {
      const double d = (o.torque - m.PredictTorque(ptr.data(), o)) / o.torque_sigma;
      out.push_back({id, "torque", o.id_a, o.iq_a, o.speed_rpm, d * d, 1});
    }
  }
  return out;
}

// Regions of the operating space where mismatches are located, and the
// chi^2 of the normalised residuals in each against its degrees of freedom.

std::vector<RegionStat> RegionStats(const std::vector<Z>& zs) {
  struct Region { std::string signal, where; std::function<bool(const Z&)> in; };
  auto mag = [](const Z& z) { return std::hypot(z.id_a, z.iq_a); };
  const std::vector<Region> regions = {
      {"hf_current", "low fundamental current, |i| < 25 A, standstill", [&](const Z& z) { return z.speed_rpm == 0 && mag(z) < 25; }},
      {"hf_current", "high fundamental current, |i| >= 25 A, standstill", [&](const Z& z) { return z.speed_rpm == 0 && mag(z) >= 25; }},
      {"hf_current", "rotating points", [&](const Z& z) { return z.speed_rpm != 0; }},
      {"dc_voltage", "low fundamental current, |i| < 25 A, standstill", [&](const Z& z) { return mag(z) < 25; }},
      {"dc_voltage", "high fundamental current, |i| >= 25 A, standstill", [&](const Z& z) { return mag(z) >= 25; }},
      {"steady_state_voltage", "steady state at speed", [](const Z&) { return true; }},
      {"torque", "steady state at speed", [](const Z&) { return true; }},
  };
  std::vector<RegionStat> out;
  for (const auto& r : regions) {
    RegionStat st;
    st.signal = r.signal;
    st.where = r.where;
    for (const auto& z : zs) {
      if (z.signal != r.signal || !r.in(z)) continue;
      st.chi2 += z.z2;
      st.k += z.dof;
      st.points.push_back({z.z2 / z.dof, z.point});
    }
    out.push_back(std::move(st));
  }
  return out;
}

// Regions whose significance reaches `threshold`.
std::vector<Mismatch> Locate(const std::vector<Z>& zs, double threshold) {
  std::vector<Mismatch> out;
  for (auto& r : RegionStats(zs)) {
    if (r.k == 0 || r.Sigma() < threshold) continue;
    std::sort(r.points.rbegin(), r.points.rend());
    Mismatch mm;
    mm.signal = r.signal;
    mm.where = r.where;
    mm.significance_sigma = r.Sigma();
    for (const auto& [v, name] : r.points) if (v > 4.0 && mm.points.size() < 12) mm.points.push_back(name);
    out.push_back(mm);
  }
  return out;
}

// Practical significance of a candidate (beyond BIC and the parameter's
// distance from neutral): it must explain a real share of what is wrong.
// Either the relative residual RMS over every observable falls by
// `min_relative_improvement`, or the candidate removes at least half of the
// chi^2 excess of a region that is located as mismatched. The second form
// keeps one unexplained gross region (or noisy torque rows near zero torque,
// which dominate a relative RMS) from hiding an effect that clearly explains
// another region.
bool PracticallySignificant(const std::vector<Z>& before, const std::vector<Z>& after, double rms_before,
                            double rms_after, const DiagnoseOptions& opt) {
  if (rms_after <= (1.0 - opt.min_relative_improvement) * rms_before) return true;
  const auto rb = RegionStats(before), ra = RegionStats(after);
  for (size_t k = 0; k < rb.size(); ++k) {
    if (rb[k].k == 0 || rb[k].Sigma() < opt.mismatch_sigma) continue;
    const double excess_before = rb[k].chi2 - rb[k].k, excess_after = ra[k].chi2 - ra[k].k;
    if (excess_after <= 0.5 * excess_before) return true;
  }
  return false;
}

}  // namespace fluxcal::diag::detail
