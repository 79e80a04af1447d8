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
    const Complex d0 = (o.i0 - i0) / o.sigma0, d1 = (o.i1 - i1) / o.sigma1;
    out.push_back({o.point, "hf_current", o.id_a, o.iq_a, o.speed_rpm, std::norm(d0) + std::norm(d1), 4,
                   {d0.real(), d0.imag(), d1.real(), d1.imag()}, o.theta});
  }
  for (const auto& o : m.dc) {
    const Complex d = (o.u - m.PredictDc(ptr.data(), o)) / o.sigma;
    out.push_back({o.point, "dc_voltage", o.id_a, o.iq_a, 0.0, std::norm(d), 2, {d.real(), d.imag()}, o.theta});
  }
  for (size_t k = 0; k < m.ss.size(); ++k) {
    const auto& o = m.ss[k];
    const std::string id = absl::StrFormat("steady_state[%d]", k);
    out.push_back({id, "steady_state_voltage", o.id_a, o.iq_a, o.speed_rpm,
                   std::norm((o.u - m.PredictSs(ptr.data(), o)) / o.sigma), 2, {}});
    if (o.has_torque) {
      const double d = (o.torque - m.PredictTorque(ptr.data(), o)) / o.torque_sigma;
      out.push_back({id, "torque", o.id_a, o.iq_a, o.speed_rpm, d * d, 1, {}});
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

std::vector<Mismatch> AnglePatterns(const std::vector<Z>& zs, double threshold) {
  std::vector<Mismatch> out;
  for (const char* signal : {"hf_current", "dc_voltage"}) {
    std::vector<const Z*> pts;
    for (const auto& z : zs) {
      if (z.signal == signal && z.speed_rpm == 0 && !z.r.empty()) pts.push_back(&z);
    }
    // A pattern of order k needs well more points than its 3 coefficients
    // per component.
    if (pts.size() < 12) continue;
    for (int k : {1, 2, 3, 4, 6}) {
      // Per component: least squares on [1, cos k theta, sin k theta]; the
      // chi^2 the two angle terms explain beyond the constant is
      // chi^2(2) per component for pure noise.
      Eigen::MatrixXd A(pts.size(), 3);
      for (size_t i = 0; i < pts.size(); ++i) {
        A(i, 0) = 1.0;
        A(i, 1) = std::cos(k * pts[i]->theta);
        A(i, 2) = std::sin(k * pts[i]->theta);
      }
      const auto qr = A.colPivHouseholderQr();
      if (qr.rank() < 3) continue;
      double explained = 0;
      int dof = 0;
      const size_t nc = pts[0]->r.size();
      std::vector<double> fitted_sq(pts.size(), 0.0);
      for (size_t c = 0; c < nc; ++c) {
        Eigen::VectorXd y(pts.size());
        for (size_t i = 0; i < pts.size(); ++i) y(i) = pts[i]->r[c];
        const Eigen::VectorXd x = qr.solve(y);
        const double mean = y.mean();
        const Eigen::VectorXd with = A * x;
        // RSS(constant) - RSS(constant + pattern) = |fit - mean|^2.
        for (size_t i = 0; i < pts.size(); ++i) {
          const double d = with(i) - mean;
          explained += d * d;
          fitted_sq[i] += d * d;
        }
        dof += 2;
      }
      const double sigma = (explained - dof) / std::sqrt(2.0 * dof);
      if (sigma < threshold) continue;
      Mismatch mm;
      mm.signal = signal;
      mm.kind = "angle_pattern";
      mm.order = k;
      mm.where = absl::StrFormat("standstill, varying with the rotor angle as cos(%d theta_e + phase)", k);
      mm.significance_sigma = sigma;
      std::vector<std::pair<double, std::string>> worst;
      for (size_t i = 0; i < pts.size(); ++i) worst.push_back({fitted_sq[i], pts[i]->point});
      std::sort(worst.rbegin(), worst.rend());
      for (size_t i = 0; i < worst.size() && i < 6; ++i) mm.points.push_back(worst[i].second);
      out.push_back(mm);
    }
  }
  return out;
}

// Regions whose significance reaches `threshold`, then the angle patterns.
std::vector<Mismatch> Locate(const std::vector<Z>& zs, double threshold) {
  std::vector<Mismatch> out;
  for (auto& r : RegionStats(zs)) {
    if (r.k == 0 || r.Sigma() < threshold) continue;
    std::sort(r.points.rbegin(), r.points.rend());
    Mismatch mm;
    mm.signal = r.signal;
    mm.kind = "region";
    mm.where = r.where;
    mm.significance_sigma = r.Sigma();
    for (const auto& [v, name] : r.points) if (v > 4.0 && mm.points.size() < 12) mm.points.push_back(name);
    out.push_back(mm);
  }
  for (auto& mm : AnglePatterns(zs, threshold)) out.push_back(std::move(mm));
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
