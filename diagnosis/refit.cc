#include "diagnosis/internal.h"

#include <algorithm>
#include <cmath>
#include <functional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "ceres/ceres.h"

namespace fluxcal::diag::detail {

// One cost functor per observation (numeric derivatives: the model is a
// small linear solve per point).
class ObservationResidual {
 public:
  ObservationResidual(const Model* m, int kind, int index) : m_(m), kind_(kind), index_(index) {}
  bool operator()(const double* const* p, double* r) const {
    if (kind_ == 0) {
      const auto& o = m_->hf[index_];
      Complex i0, i1;
      m_->PredictHf(p, o, &i0, &i1);
      const Complex d0 = (o.i0 - i0) / o.sigma0, d1 = (o.i1 - i1) / o.sigma1;
      r[0] = d0.real(); r[1] = d0.imag(); r[2] = d1.real(); r[3] = d1.imag();
    } else if (kind_ == 1) {
      const auto& o = m_->dc[index_];
      const Complex d = (o.u - m_->PredictDc(p, o)) / o.sigma;
      r[0] = d.real(); r[1] = d.imag();
    } else if (kind_ == 2) {
      const auto& o = m_->ss[index_];
      const Complex d = (o.u - m_->PredictSs(p, o)) / o.sigma;
      r[0] = d.real(); r[1] = d.imag();
    } else {
      const auto& o = m_->ss[index_];
      r[0] = (o.torque - m_->PredictTorque(p, o)) / o.torque_sigma;
    }
    return true;
  }
  static int NumResiduals(int kind) { return kind == 0 ? 4 : (kind == 3 ? 1 : 2); }

 private:
  const Model* m_;
  int kind_, index_;
};

// Relative residual RMS over every observable (dimensionless). HF phasors
// and steady-state voltages are relative to their own magnitude (never near
// zero); held DC voltages and torques are relative to the RMS magnitude of
// their kind over the set (Model::dc_scale_v, torque_scale_nm), because a
// row near zero volts or zero torque would otherwise turn its noise into a
// large relative error and dominate the RMS.
double RelativeRms(const Model& m, const Params& p) {
  const auto ptr = p.Ptrs();
  double s = 0;
  int n = 0;
  for (const auto& o : m.hf) {
    Complex i0, i1;
    m.PredictHf(ptr.data(), o, &i0, &i1);
    s += (std::norm(o.i0 - i0) + std::norm(o.i1 - i1)) / (o.scale * o.scale);
    n += 2;
  }
  for (const auto& o : m.dc) {
    s += std::norm(o.u - m.PredictDc(ptr.data(), o)) / (m.dc_scale_v * m.dc_scale_v);
    ++n;
  }
  for (const auto& o : m.ss) {
    s += std::norm(o.u - m.PredictSs(ptr.data(), o)) / (o.scale * o.scale);
    ++n;
    if (o.has_torque) {
      const double d = (o.torque - m.PredictTorque(ptr.data(), o)) / m.torque_scale_nm;
      s += d * d;
      ++n;
    }
  }
  return n ? std::sqrt(s / n) : 0.0;
}

// Observation kinds, as ObservationResidual numbers them.

const char* KindSignal(int kind) {
  static const char* names[5] = {"hf_current", "dc_voltage", "steady_state_voltage", "torque",
                                 "dc_voltage_second_udc"};
  return names[kind];
}

// Least squares over every observation except those of kind `held_out`
// (-1: none), with the blocks in `free_blocks` free.
// Relative residual RMS of one observation kind (normalised as RelativeRms).
double RelativeRmsOf(const Model& m, const Params& p, int kind) {
  const auto ptr = p.Ptrs();
  double s = 0;
  int n = 0;
  if (kind == kHfKind) {
    for (const auto& o : m.hf) {
      Complex i0, i1;
      m.PredictHf(ptr.data(), o, &i0, &i1);
      s += (std::norm(o.i0 - i0) + std::norm(o.i1 - i1)) / (o.scale * o.scale);
      n += 2;
    }
  }
  if (kind == kDcKind) {
    for (const auto& o : m.dc) { s += std::norm(o.u - m.PredictDc(ptr.data(), o)) / (m.dc_scale_v * m.dc_scale_v); ++n; }
  }
  for (const auto& o : m.ss) {
    if (kind == kSsKind) { s += std::norm(o.u - m.PredictSs(ptr.data(), o)) / (o.scale * o.scale); ++n; }
    if (kind == kTorqueKind && o.has_torque) {
      const double d = (o.torque - m.PredictTorque(ptr.data(), o)) / m.torque_scale_nm;
      s += d * d;
      ++n;
    }
  }
  return n ? std::sqrt(s / n) : 0.0;
}

FitOut Solve(const Model& m, const Params& start, const std::vector<Block>& free_blocks, int held_out) {
  FitOut out;
  out.p = start;
  ceres::Problem problem;
  std::vector<double*> blocks;
  for (auto& x : out.p.b) blocks.push_back(x.data());
  auto add = [&](int kind, int index) {
    if (kind == held_out) return;
    if (held_out == kDcSecondUdcKind && kind == kDcKind && m.dc[index].second_udc) return;
    auto* c = new ceres::DynamicNumericDiffCostFunction<ObservationResidual>(new ObservationResidual(&m, kind, index));
    for (int k = 0; k < kNumBlocks; ++k) c->AddParameterBlock(kBlockSize[k]);
    c->SetNumResiduals(ObservationResidual::NumResiduals(kind));
    problem.AddResidualBlock(c, nullptr, blocks);
    out.n += ObservationResidual::NumResiduals(kind);
  };
  for (size_t k = 0; k < m.hf.size(); ++k) add(0, static_cast<int>(k));
  for (size_t k = 0; k < m.dc.size(); ++k) add(1, static_cast<int>(k));
  for (size_t k = 0; k < m.ss.size(); ++k) {
    add(2, static_cast<int>(k));
    if (m.ss[k].has_torque) add(3, static_cast<int>(k));
  }
  for (int k = 0; k < kNumBlocks; ++k) {
    const bool free = std::find(free_blocks.begin(), free_blocks.end(), static_cast<Block>(k)) != free_blocks.end();
    if (!free) problem.SetParameterBlockConstant(blocks[k]);
    else out.k += kBlockSize[k];
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 60;
  so.function_tolerance = 1e-10;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary sum;
  ceres::Solve(so, &problem, &sum);
  out.ok = sum.IsSolutionUsable();
  out.chi2 = 2 * sum.final_cost;
  // BIC with the noise scale estimated from the data (Gaussian likelihood
  // with unknown variance): n ln(chi2/n) + k ln n. The stated sigmas fix the
  // relative weights of the observables; their common scale is what the
  // data say, so a model error shared by all points cannot pose as physics.
  out.bic = out.n * std::log(std::max(out.chi2, 1e-300) / std::max(1, out.n)) + out.k * std::log(std::max(1, out.n));
  out.rms = RelativeRms(m, out.p);
  // Standard deviations of the effect parameters (not the base surfaces),
  // scaled by the reduced chi^2 when the fit is worse than the noise model.
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = -1;
  ceres::Covariance cov(co);
  std::vector<std::pair<const double*, const double*>> pairs;
  for (Block b : free_blocks) if (b != kBase && b != kCross) pairs.push_back({blocks[b], blocks[b]});
  if (!pairs.empty() && cov.Compute(pairs, &problem)) {
    const double scale = std::max(1.0, out.chi2 / std::max(1, out.n - out.k));
    for (Block b : free_blocks) {
      if (b == kBase || b == kCross) continue;
      std::vector<double> c(kBlockSize[b] * kBlockSize[b]);
      cov.GetCovarianceBlock(blocks[b], blocks[b], c.data());
      std::vector<double> sd;
      for (int i = 0; i < kBlockSize[b]; ++i) sd.push_back(std::sqrt(std::max(0.0, c[i * kBlockSize[b] + i] * scale)));
      out.stdev[b] = sd;
    }
  }
  return out;
}

}  // namespace fluxcal::diag::detail
