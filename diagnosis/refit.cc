#include "diagnosis/internal.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <cstdio>
#include <cstdlib>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "ceres/ceres.h"
#include "fitting/calibration.h"

namespace fluxcal::diag::detail {

// One observation's whitened residual (1, 2 or 4 components by kind).
void ObservationResidual(const Model& m, int kind, int index, const double* const* p, double* r) {
  if (kind == kHfKind) {
    const auto& o = m.hf[index];
    Complex i0, i1;
    m.PredictHf(p, o, &i0, &i1);
    const Complex d0 = (o.i0 - i0) / o.sigma0, d1 = (o.i1 - i1) / o.sigma1;
    r[0] = d0.real(); r[1] = d0.imag(); r[2] = d1.real(); r[3] = d1.imag();
  } else if (kind == kDcKind) {
    const auto& o = m.dc[index];
    const Complex d = (o.u - m.PredictDc(p, o)) / o.sigma;
    r[0] = d.real(); r[1] = d.imag();
  } else if (kind == kSsKind) {
    const auto& o = m.ss[index];
    const Complex d = (o.u - m.PredictSs(p, o)) / o.sigma;
    r[0] = d.real(); r[1] = d.imag();
  } else {
    const auto& o = m.ss[index];
    r[0] = (o.torque - m.PredictTorque(p, o)) / o.torque_sigma;
  }
}
int NumResiduals(int kind) { return kind == kHfKind ? 4 : (kind == kTorqueKind ? 1 : 2); }

// One cost function per observation. The effect blocks are differentiated
// numerically (central differences; the model is a small linear solve per
// point). The surfaces, a hundred and more spline coefficients, by the
// chain rule: an observation reads the surfaces at one operating point, so
//   dr/dc = sum_v dr/dv dv/dc,  v in (psi_d, psi_q, Ldd, Lqq, Ldq),
// with dr/dv from five probes of the model (Model::SurfaceProbe) and dv/dc
// exact and sparse from fit::SurfaceAt (25 coefficients around the point,
// 25 around the origin). Differencing every coefficient instead would cost
// a hundred model evaluations per observation and iteration.
class ObservationCost : public ceres::CostFunction {
 public:
  ObservationCost(const Model* m, int kind, int index) : m_(m), kind_(kind), index_(index) {
    set_num_residuals(NumResiduals(kind));
    for (int b = 0; b < kNumBlocks; ++b) mutable_parameter_block_sizes()->push_back(m->BlockSize(b));
  }
  bool Evaluate(double const* const* p, double* r, double** jac) const override {
    ObservationResidual(*m_, kind_, index_, p, r);
    for (int k = 0; k < num_residuals(); ++k) {
      if (!std::isfinite(r[k])) return false;
    }
    if (jac == nullptr) return true;
    const int nr = num_residuals();
    double r0[4], rp[4], rm[4];
    // Effect blocks: central differences, relative step 1e-6 (Ceres'
    // NumericDiffOptions default).
    std::vector<std::vector<double>> q(kNumBlocks);
    std::vector<const double*> ptr(kNumBlocks);
    for (int b = 0; b < kNumBlocks; ++b) {
      q[b].assign(p[b], p[b] + m_->BlockSize(b));
      ptr[b] = q[b].data();
    }
    for (int b = 1; b < kNumBlocks; ++b) {
      if (jac[b] == nullptr) continue;
      const int n = m_->BlockSize(b);
      for (int i = 0; i < n; ++i) {
        const double x = q[b][i], h = 1e-6 * std::max(1.0, std::abs(x));
        q[b][i] = x + h;
        ObservationResidual(*m_, kind_, index_, ptr.data(), rp);
        q[b][i] = x - h;
        ObservationResidual(*m_, kind_, index_, ptr.data(), rm);
        q[b][i] = x;
        for (int k = 0; k < nr; ++k) jac[b][k * n + i] = (rp[k] - rm[k]) / (2 * h);
      }
    }
    if (jac[kBase] != nullptr) {
      const int n = m_->BlockSize(kBase);
      std::fill(jac[kBase], jac[kBase] + nr * n, 0.0);
      auto& probe = m_->probe;
      probe = {};
      probe.on = true;
      ObservationResidual(*m_, kind_, index_, p, r0);
      if (probe.seen) {
        const double id = probe.id_a, iq = probe.iq_a;
        const fit::SurfacePoint sp = fit::SurfaceAt(m_->surf, p[kBase], id, iq);
        // Steps: 1e-6 of the value's own scale (an inductance of the
        // point, the magnet flux), central.
        const double l_scale = std::max({std::abs(sp.value[fit::kLdd]), std::abs(sp.value[fit::kLqq]), 1e-9});
        const double psi_scale = std::max({std::abs(m_->psi_nom), std::abs(sp.value[fit::kPsiD]), 1e-6});
        double drdv[4][fit::kSurfaceValues] = {};
        for (int v = 0; v < fit::kSurfaceValues; ++v) {
          const double h = 1e-6 * (v <= fit::kPsiQ ? psi_scale : l_scale);
          probe.delta[v] = h;
          ObservationResidual(*m_, kind_, index_, p, rp);
          probe.delta[v] = -h;
          ObservationResidual(*m_, kind_, index_, p, rm);
          probe.delta[v] = 0.0;
          for (int k = 0; k < nr; ++k) drdv[k][v] = (rp[k] - rm[k]) / (2 * h);
        }
        for (const auto& [idx, g] : sp.grad) {
          for (int k = 0; k < nr; ++k) {
            double s = 0;
            for (int v = 0; v < fit::kSurfaceValues; ++v) s += drdv[k][v] * g[v];
            jac[kBase][k * n + idx] += s;
          }
        }
      }
      probe = {};
    }
    return true;
  }

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

namespace {

// The free parameters of a refit as one vector: the surfaces' coefficients
// (the family's psi_pm slot 0 excluded) and the free effect blocks, in
// block order.
struct Layout {
  std::vector<bool> free;          // per block
  std::vector<int> block_offset;   // per block: offset of its element 0 in x (kBase: one before its first free)
  int n = 0;
  int surf_offset = -1;            // offset of coefficient 1 of kBase
  Layout(const Model& m, const std::vector<Block>& free_blocks) : free(kNumBlocks, false), block_offset(kNumBlocks, 0) {
    for (int b = 0; b < kNumBlocks; ++b) {
      if (std::find(free_blocks.begin(), free_blocks.end(), static_cast<Block>(b)) == free_blocks.end()) continue;
      free[b] = true;
      if (b == kBase) {
        surf_offset = n;
        block_offset[b] = n - 1;   // so that coefficient i sits at x[block_offset + i], i >= 1
        n += m.BlockSize(kBase) - 1;
      } else {
        block_offset[b] = n;
        n += m.BlockSize(b);
      }
    }
  }
  static int First(int b) { return b == kBase ? 1 : 0; }
  void Scatter(const Eigen::VectorXd& x, const Model& m, Params* p) const {
    for (int b = 0; b < kNumBlocks; ++b) {
      if (!free[b]) continue;
      for (int i = First(b); i < m.BlockSize(b); ++i) p->b[b][i] = x(block_offset[b] + i);
    }
  }
  Eigen::VectorXd Gather(const Params& p, const Model& m) const {
    Eigen::VectorXd x(n);
    for (int b = 0; b < kNumBlocks; ++b) {
      if (!free[b]) continue;
      for (int i = First(b); i < m.BlockSize(b); ++i) x(block_offset[b] + i) = p.b[b][i];
    }
    return x;
  }
};

struct Linearised {
  Eigen::VectorXd r;   // whitened residuals
  Eigen::MatrixXd J;   // d r / d x
  bool ok = true;
};

// Residuals and their Jacobian over the observations of `obs` at `p`
// (ObservationCost's derivatives: central differences for effect blocks,
// the chain rule through fit::SurfaceAt for the surfaces).
Linearised Linearise(const Model& m, const std::vector<std::pair<int, int>>& obs, int rows, const Layout& L,
                     const Params& p, bool jacobian) {
  Linearised out;
  out.r.resize(rows);
  if (jacobian) out.J = Eigen::MatrixXd::Zero(rows, L.n);
  const auto ptr = p.Ptrs();
  int row = 0;
  std::vector<std::vector<double>> jb(kNumBlocks);
  std::vector<double*> jp(kNumBlocks, nullptr);
  for (const auto& [kind, index] : obs) {
    ObservationCost cost(&m, kind, index);
    const int nr = NumResiduals(kind);
    if (jacobian) {
      for (int b = 0; b < kNumBlocks; ++b) {
        if (!L.free[b]) { jp[b] = nullptr; continue; }
        jb[b].assign(static_cast<size_t>(nr) * m.BlockSize(b), 0.0);
        jp[b] = jb[b].data();
      }
    }
    double r[4];
    if (!cost.Evaluate(ptr.data(), r, jacobian ? jp.data() : nullptr)) out.ok = false;
    for (int k = 0; k < nr; ++k) {
      out.r(row + k) = r[k];
      if (!jacobian) continue;
      for (int b = 0; b < kNumBlocks; ++b) {
        if (jp[b] == nullptr) continue;
        const int n = m.BlockSize(b);
        for (int i = L.First(b); i < n; ++i) out.J(row + k, L.block_offset[b] + i) = jb[b][k * n + i];
      }
    }
    row += nr;
  }
  return out;
}

// J^T J as a symmetric rank update (half the products of the general one).
Eigen::MatrixXd Normal(const Eigen::MatrixXd& J) {
  Eigen::MatrixXd A = Eigen::MatrixXd::Zero(J.cols(), J.cols());
  A.selfadjointView<Eigen::Lower>().rankUpdate(J.transpose());
  return A.selfadjointView<Eigen::Lower>();
}

// The penalty's normal matrix S = R^T R on the surfaces' coefficients
// 1..k-1, embedded in x's layout.
Eigen::MatrixXd PenaltyNormal(const Model& m, const Layout& L) {
  Eigen::MatrixXd S = Eigen::MatrixXd::Zero(L.n, L.n);
  if (L.surf_offset < 0 || m.surf_R.rows() == 0) return S;
  const int k = m.BlockSize(kBase);
  const Eigen::MatrixXd B = m.surf_R.transpose() * m.surf_R;
  S.block(L.surf_offset, L.surf_offset, k - 1, k - 1) = B.block(1, 1, k - 1, k - 1);
  return S;
}

// Bayesian information criterion of a penalised least-squares fit:
// n ln(RSS / n) + k_eff ln n, k_eff = tr((J^T J + lambda S)^-1 J^T J) the
// effective parameters (Hastie & Tibshirani, Generalized Additive Models,
// sec. 3.5; with the noise scale estimated from the data: the stated sigmas
// fix the relative weights of the observables, their common scale is what
// the data say, so a model error shared by all points cannot pose as
// physics).
double Bic(double rss, double k_eff, int n) {
  return n * std::log(std::max(rss, 1e-300) / std::max(1, n)) + k_eff * std::log(std::max(1, n));
}

}  // namespace

// Whether the surfaces of `p` are positive definite over the box the HF
// points span, on a 25 x 25 grid (as the fit requires of its candidates,
// fitting/select.cc): a refit whose surfaces bend Lqq negative between two
// measured levels drives the open-loop replay (evidence.cc) into a flux
// that two currents share, and it runs away (a bridge-knee machine's clean
// recording: Lqq -0.4 mH at 26 % below its top current, the replay at
// 1e40 A). Only the surfaces are judged, so the penalty weight of a refit
// is chosen among physical ones. The grid is twice as fine as the fit's:
// the joint refit's Lqq on the bridge-knee machine with a position offset
// swung 50 -> 150 -> -15 uH within 10 A of its top current, between two
// nodes of a 13 x 13 grid (the replay there 40 A off the recording).
bool SurfacesPositiveDefinite(const Model& m, const Params& p) {
  if (m.hf.empty()) return true;
  double id_lo = m.hf[0].id_a, id_hi = id_lo, iq_lo = m.hf[0].iq_a, iq_hi = iq_lo;
  for (const auto& h : m.hf) {
    id_lo = std::min(id_lo, h.id_a);
    id_hi = std::max(id_hi, h.id_a);
    iq_lo = std::min(iq_lo, h.iq_a);
    iq_hi = std::max(iq_hi, h.iq_a);
  }
  const fit::SurfaceEvaluator surf(m.surf, p.b[kBase]);
  constexpr int kNodes = 24;
  for (int i = 0; i <= kNodes; ++i) {
    for (int j = 0; j <= kNodes; ++j) {
      const double id = id_lo + (id_hi - id_lo) * i / kNodes, iq = iq_lo + (iq_hi - iq_lo) * j / kNodes;
      double ldd, lqq, ldq;
      surf.Eval(id, iq, nullptr, nullptr, &ldd, &lqq, &ldq);
      if (!fit::NotPositiveDefiniteReason(ldd, lqq, ldq).empty()) return false;
    }
  }
  return true;
}

// A damped Gauss-Newton (Levenberg-Marquardt) on the penalised objective
//   J(x) = |r(x)|^2 + lambda |R c|^2,
// x the free parameters, c the surfaces' coefficients. The penalty weight
// is chosen by the same criterion models are compared by: at the
// converged point, the problem linearised, lambda on a log grid around the
// calibration's minimises the BIC with the effective parameters k_eff;
// then converged again at that lambda. Why per refit: an effect that
// explains a pattern the surfaces could only follow by bending lets them be
// smoother; with lambda held at the plain fit's -- which chose it on data
// the effect had roughened -- the surfaces keep absorbing the effect and
// it is never seen (a 0.02 rad angle-sensor harmonic on the twin: the plain
// fit interpolated with 97 effective parameters of 145).
FitOut Solve(const Model& m, const Params& start, const std::vector<Block>& free_blocks, int held_out,
             bool choose_lambda) {
  FitOut out;
  out.p = start;
  std::vector<std::pair<int, int>> obs;
  int rows = 0;
  auto add = [&](int kind, int index) {
    if (kind == held_out) return;
    if (held_out == kDcSecondUdcKind && kind == kDcKind && m.dc[index].second_udc) return;
    obs.push_back({kind, index});
    rows += NumResiduals(kind);
  };
  for (size_t k = 0; k < m.hf.size(); ++k) add(kHfKind, static_cast<int>(k));
  for (size_t k = 0; k < m.dc.size(); ++k) add(kDcKind, static_cast<int>(k));
  for (size_t k = 0; k < m.ss.size(); ++k) {
    add(kSsKind, static_cast<int>(k));
    if (m.ss[k].has_torque) add(kTorqueKind, static_cast<int>(k));
  }
  out.n = rows;
  const Layout L(m, free_blocks);
  const Eigen::MatrixXd S = PenaltyNormal(m, L);
  const bool penalised = S.any();
  double lambda = penalised ? std::max(m.surf_lambda, m.surf_lambda_floor) : 0.0;
  Eigen::VectorXd x = L.Gather(out.p, m);
  auto objective = [&](const Linearised& lin, const Eigen::VectorXd& xv) {
    return lin.r.squaredNorm() + (penalised ? lambda * xv.dot(S * xv) : 0.0);
  };
  Linearised lin = Linearise(m, obs, rows, L, out.p, true);
  if (!lin.ok) return out;
  double f = objective(lin, x);
  double mu = 1e-6;
  // Converges `iterations` LM steps at the current lambda.
  auto converge = [&](int iterations) {
    for (int it = 0; it < iterations; ++it) {
      Eigen::MatrixXd A = Normal(lin.J) + lambda * S;
      const Eigen::VectorXd g = lin.J.transpose() * lin.r + lambda * (S * x);
      bool stepped = false;
      for (int tries = 0; tries < 12; ++tries) {
        Eigen::MatrixXd Ad = A;
        Ad.diagonal() += mu * A.diagonal().cwiseMax(1e-12);
        const Eigen::VectorXd dx = -Ad.ldlt().solve(g);
        if (!dx.allFinite()) { mu *= 10; continue; }
        const Eigen::VectorXd xn = x + dx;
        Params pn = out.p;
        L.Scatter(xn, m, &pn);
        Linearised ln = Linearise(m, obs, rows, L, pn, false);
        const double fn = ln.ok ? objective(ln, xn) : std::numeric_limits<double>::infinity();
        if (fn <= f) {
          const double rel = (f - fn) / std::max(f, 1e-300);
          x = xn;
          out.p = pn;
          f = fn;
          mu = std::max(1e-12, mu / 10);
          lin = Linearise(m, obs, rows, L, out.p, true);
          stepped = true;
          // Converged when a step lowers the objective by less than 1e-6 of
          // itself. The residuals are whitened, so the objective is a chi^2
          // of n = `rows` terms; a relative change of 1e-6 moves the BIC
          // (n ln chi^2) by n * 1e-6 < 0.01 for any set here, a thousandth
          // of the threshold that admits an effect, and a parameter by
          // about sqrt(1e-6 chi^2) ~ 0.02 of its standard deviation.
          if (rel < 1e-6 || dx.norm() < 1e-10 * (1 + x.norm())) return;
          break;
        }
        mu *= 10;
      }
      if (!stepped) return;
    }
  };
  converge(40);
  if (penalised && choose_lambda) {
    // lambda by the BIC of the problem linearised at the solution, for
    // every lambda at the price of one eigendecomposition (the
    // Demmler-Reinsch basis of fit.cc's SolveLinear): with B = S + eps I =
    // L L^T and L^-1 A L^-T = U D U^T (A = J^T J), M = L^-T U,
    //   (A + lambda B)^-1 = M (D + lambda)^-1 M^T,
    //   k_eff = sum d_i / (d_i + lambda),
    //   dx(lambda) = -M (D + lambda)^-1 M^T (J^T r + lambda B x).
    // The grid spans 14 decades around the ratio of the two matrices'
    // scales (the plain fit's lambda was chosen for other residuals, on
    // data an effect may have roughened).
    const Eigen::MatrixXd A = Normal(lin.J);
    Eigen::MatrixXd B = S;
    const double eps = 1e-9 * S.trace() / L.n;
    B.diagonal().array() += eps;
    Eigen::LLT<Eigen::MatrixXd> chol(B);
    if (chol.info() == Eigen::Success) {
      const Eigen::MatrixXd Linv = chol.matrixL().solve(Eigen::MatrixXd::Identity(L.n, L.n));
      const Eigen::MatrixXd C = Linv * A * Linv.transpose();
      Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (C + C.transpose()));
      const Eigen::VectorXd d = es.eigenvalues().cwiseMax(0.0);
      const Eigen::MatrixXd M = Linv.transpose() * es.eigenvectors();
      const Eigen::MatrixXd JM = lin.J * M;
      const Eigen::VectorXd z1 = M.transpose() * (lin.J.transpose() * lin.r), z2 = M.transpose() * (B * x);
      const double unit = A.trace() / std::max(S.trace(), 1e-300);
      double best = std::numeric_limits<double>::infinity(), best_lam = lambda;
      for (int e = 0; e <= 56; ++e) {
        const double lam = unit * std::pow(10.0, -10.0 + 0.25 * e);
        const Eigen::VectorXd w = ((z1 + lam * z2).array() / (d.array() + lam)).matrix();
        const double rss = (lin.r - JM * w).squaredNorm();
        const double k_eff = (d.array() / (d.array() + lam)).sum();
        const double bic = Bic(rss, k_eff, rows);
        if (lam < m.surf_lambda_floor) continue;
        if (bic >= best) continue;
        // The linearised step to this lambda's solution, judged physical
        // before it is preferred (SurfacesPositiveDefinite).
        Params pl = out.p;
        L.Scatter(x - M * w, m, &pl);
        if (!SurfacesPositiveDefinite(m, pl)) continue;
        best = bic;
        best_lam = lam;
      }
      if (best_lam != lambda) {
        lambda = best_lam;
        f = objective(lin, x);
        mu = 1e-6;
        converge(40);
      }
      // The scan judged the linearised steps; the converged surfaces are
      // judged again, and where they are not physical the weight rises a
      // quarter decade at a time (up to four decades) until they are: the
      // smoothest of the nearby solutions a machine could have.
      for (int step = 0; step < 16 && !SurfacesPositiveDefinite(m, out.p); ++step) {
        lambda *= std::pow(10.0, 0.25);
        f = objective(lin, x);
        mu = 1e-6;
        converge(40);
      }
    }
  }
  out.ok = lin.ok && x.allFinite();
  out.lambda = lambda;
  out.chi2 = lin.r.squaredNorm();
  out.penalty = penalised ? lambda * x.dot(S * x) : 0.0;
  const Eigen::MatrixXd JtJ = Normal(lin.J);
  Eigen::MatrixXd A = JtJ + lambda * S;
  A.diagonal().array() += 1e-12 * std::max(1e-300, A.diagonal().maxCoeff());
  const Eigen::MatrixXd Ainv = A.ldlt().solve(Eigen::MatrixXd::Identity(L.n, L.n));
  out.k_eff = (Ainv * JtJ).trace();
  out.bic = Bic(out.chi2, out.k_eff, rows);
  out.rms = RelativeRms(m, out.p);
  // Standard deviations of the effect parameters (not the surfaces): the
  // posterior covariance (J^T J + lambda S)^-1, scaled by the reduced chi^2
  // when the fit is worse than the stated sigmas (never below them: the
  // classes' stated sigmas carry model floors of different sizes, so a
  // reduced chi^2 below one says little about any one parameter).
  const double scale = std::max(1.0, out.chi2 / std::max(1.0, rows - out.k_eff));
  int k_effects = 0;
  for (Block b : free_blocks) {
    if (b == kBase || !L.free[b]) continue;
    std::vector<double> sd;
    for (int i = 0; i < kBlockSize[b]; ++i) {
      const int c = L.block_offset[b] + i;
      sd.push_back(std::sqrt(std::max(0.0, Ainv(c, c) * scale)));
    }
    out.stdev[b] = sd;
    k_effects += kBlockSize[b];
  }
  out.k = static_cast<int>(std::lround(out.k_eff));
  (void)k_effects;
  return out;
}

}  // namespace fluxcal::diag::detail
