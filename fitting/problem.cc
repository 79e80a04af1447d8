#include "fitting/problem.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "fitting/apparent_residual.h"
#include "fitting/dynamic_cost.h"
#include "fitting/flux_residual.h"
#include "fitting/inductance_residual.h"
#include "fitting/prior_residual.h"
#include "fitting/torque_residual.h"
#include "physics/speed.h"

namespace fluxcal::fit::internal {
namespace {

using affine::Affine;

std::vector<double> InitialParams(const Family& f, const FitData& d) {
  const double psi_pm = d.psi_pm_prior_wb.value_or(0.01);
  if (f.kind == Family::kAnalytic) {
    // Start from the inductance data themselves.
    double ld = 0, lq = 0;
    for (const auto& o : d.inductances) { ld += o.ldd_h; lq += o.lqq_h; }
    const double n = std::max<size_t>(1, d.inductances.size());
    if (d.inductances.empty()) { ld = 1.8e-4; lq = 3.5e-4; } else { ld /= n; lq /= n; }
    return {psi_pm, ld, lq, 400.0, 300.0, 0.0, 100.0};
  }
  std::vector<double> p(f.NumParams(), 0.0);
  p[0] = psi_pm;
  return p;
}

// The flux level the data speak of, Wb: the largest |psi| of the flux rows
// and nodes, and L |i| of the inductance points (what a linear inductance
// links there); 1 mWb when the data say nothing (no current anywhere).
double DataFluxScaleWb(const FitData& d) {
  double scale = 0;
  for (const auto& obs : d.inductances) {
    scale = std::max(scale, std::hypot(std::abs(obs.ldd_h * obs.id_a), std::abs(obs.lqq_h * obs.iq_a)));
  }
  for (const auto& s : d.steady_state) {
    double pd, pq;
    SteadyStateFlux(s, d.pole_pairs, d.rs_ohm, d.f_pwm_hz, &pd, &pq);
    if (std::isfinite(pd) && std::isfinite(pq)) scale = std::max(scale, std::hypot(pd, pq));
  }
  for (const auto& f : d.fluxes) scale = std::max(scale, std::hypot(f.psi_d_wb, f.psi_q_wb));
  return std::isfinite(scale) && scale > 0 ? scale : 1e-3;
}

// Where each residual goes: to the Ceres problem (analytic family) or,
// evaluated once in affine arithmetic, to the linear rows (linear
// families): one set of residual equations either way.
class ResidualSink {
 public:
  ResidualSink(Built* built, int num_params, bool linear, double robust_scale)
      : built_(built), num_params_(num_params), linear_(linear), robust_scale_(robust_scale) {
    // Parameter j as the affine form p_j.
    if (linear_) {
      unit_.resize(num_params_);
      for (int j = 0; j < num_params_; ++j) unit_[j].t.push_back({j, 1.0});
    }
  }

  // A residual F(args...); `robust`: under the Huber loss.
  template <typename F, typename... Args>
  void Add(bool robust, const Args&... args) {
    if (linear_) {
      const F functor(args...);
      const Affine* pp[1] = {unit_.data()};
      Affine r;
      functor(pp, &r);
      built_->linear_rows.push_back(std::move(r));
      built_->robust.push_back(robust);
    } else {
      built_->problem->AddResidualBlock(DynamicCost(new F(args...), num_params_),
                                        robust ? new ceres::HuberLoss(robust_scale_) : nullptr,
                                        built_->params.data());
    }
    ++built_->residuals;
  }

 private:
  Built* built_;
  const int num_params_;
  const bool linear_;
  const double robust_scale_;
  std::vector<Affine> unit_;
};

}  // namespace

double RowFluxSigmaWb(double speed_rpm, int pole_pairs, double psi_d_wb, double psi_q_wb) {
  const double we = physics::RpmToElectricalRadS(std::abs(speed_rpm), pole_pairs);
  return 0.05 / std::max(we, 1.0) + 0.005 * std::hypot(psi_d_wb, psi_q_wb);
}
double RowTorqueSigmaNm(double torque_nm) { return 0.02 + 0.005 * std::abs(torque_nm); }

double DataCurrentScaleA(const FitData& d) {
  double scale = 0;
  for (const auto& o : d.inductances) scale = std::max(scale, std::hypot(o.id_a, o.iq_a));
  for (const auto& f : d.fluxes) scale = std::max(scale, std::hypot(f.id_a, f.iq_a));
  if (scale > 0) return scale;
  for (const auto& s : d.steady_state) scale = std::max(scale, std::hypot(s.id_a, s.iq_a));
  return scale;
}

double RowRelativeRipple(const SteadyStateObservation& s, double current_scale_a) {
  if (!s.current_ripple_a) return 0.0;
  const double i = std::max(std::hypot(s.id_a, s.iq_a), kRippleCurrentFloor * current_scale_a);
  return i > 0 ? *s.current_ripple_a / i : 0.0;
}

double RowSigmaWb(const SteadyStateObservation& s, int pole_pairs, double current_scale_a, double psi_d_wb,
                  double psi_q_wb) {
  const double r = RowRelativeRipple(s, current_scale_a);
  const double ripple = 0.5 * kRippleCurvature * r * r * std::hypot(psi_d_wb, psi_q_wb);
  return std::hypot(RowFluxSigmaWb(s.speed_rpm, pole_pairs, psi_d_wb, psi_q_wb), ripple);
}

Built Build(const Family& fam, const FitData& d, const FitOptions& o) {
  Built b;
  b.params = InitialParams(fam, d);
  const bool linear = fam.kind != Family::kAnalytic;
  if (!linear) b.problem = std::make_unique<ceres::Problem>();
  const int n = fam.NumParams();
  double* p = b.params.data();
  ResidualSink sink(&b, n, linear, o.robust_scale);
  using L = InductanceComponent;
  for (const auto& obs : d.inductances) {
    const double sd = std::max(obs.ldd_h_std, o.relative_sigma_floor * std::abs(obs.ldd_h));
    const double sq = std::max(obs.lqq_h_std, o.relative_sigma_floor * std::abs(obs.lqq_h));
    if (o.differential_as_apparent) {
      sink.Add<ApparentResidual>(true, fam, obs.id_a, obs.iq_a, L::kLdd, obs.ldd_h, sd);
      sink.Add<ApparentResidual>(true, fam, obs.id_a, obs.iq_a, L::kLqq, obs.lqq_h, sq);
      continue;
    }
    sink.Add<InductanceResidual>(true, fam, obs.id_a, obs.iq_a, L::kLdd, obs.ldd_h, sd, obs.hf_orbit);
    sink.Add<InductanceResidual>(true, fam, obs.id_a, obs.iq_a, L::kLqq, obs.lqq_h, sq, obs.hf_orbit);
    if (obs.ldq_h) {
      const double mean = 0.5 * (obs.ldd_h + obs.lqq_h);
      const double sx = std::max(obs.ldq_h_std, o.relative_sigma_floor * mean);
      sink.Add<InductanceResidual>(true, fam, obs.id_a, obs.iq_a, L::kLdq, *obs.ldq_h, sx, obs.hf_orbit);
    }
  }
  const double current_scale = DataCurrentScaleA(d);
  for (const auto& s : d.steady_state) {
    double pd, pq;
    SteadyStateFlux(s, d.pole_pairs, d.rs_ohm, d.f_pwm_hz, &pd, &pq);
    const double sigma = RowSigmaWb(s, d.pole_pairs, current_scale, pd, pq);
    sink.Add<FluxResidual>(true, fam, s.id_a, s.iq_a, FluxComponent::kPsiD, pd, sigma);
    sink.Add<FluxResidual>(true, fam, s.id_a, s.iq_a, FluxComponent::kPsiQ, pq, sigma);
    if (s.torque_nm) {
      const double st = RowTorqueSigmaNm(*s.torque_nm);
      sink.Add<TorqueResidual>(true, fam, d.pole_pairs, s.id_a, s.iq_a, *s.torque_nm, st);
    }
  }
  for (const auto& f : d.fluxes) {
    sink.Add<FluxResidual>(true, fam, f.id_a, f.iq_a, FluxComponent::kPsiD, f.psi_d_wb, f.psi_std_wb);
    sink.Add<FluxResidual>(true, fam, f.id_a, f.iq_a, FluxComponent::kPsiQ, f.psi_q_wb, f.psi_std_wb);
  }
  if (d.psi_pm_prior_wb) {
    b.has_prior = true;
    // The prior's sigma is relative to the declared value; a declared 0 (a
    // synchronous reluctance machine, no magnet) is as certain, measured
    // against the machine's own flux level (a zero sigma made the residual
    // 0/0 and crashed the analytic family's covariance).
    const double level = *d.psi_pm_prior_wb > 0 ? *d.psi_pm_prior_wb : DataFluxScaleWb(d);
    sink.Add<PriorResidual>(false, *d.psi_pm_prior_wb, o.psi_pm_prior_relative_std * level);
  }
  if (fam.kind == Family::kAnalytic) {
    // Physical bounds; ix_a is a fixed shape constant (with g ~ 0 it would be
    // unidentifiable).
    b.problem->SetParameterLowerBound(p, 1, 1e-6);
    b.problem->SetParameterLowerBound(p, 2, 1e-6);
    b.problem->SetParameterLowerBound(p, 3, 20.0);
    b.problem->SetParameterLowerBound(p, 4, 20.0);
    b.problem->SetParameterUpperBound(p, 3, 1e5);
    b.problem->SetParameterUpperBound(p, 4, 1e5);
    b.problem->SetManifold(p, new ceres::SubsetManifold(n, {6}));
  }
  return b;
}

}  // namespace fluxcal::fit::internal
