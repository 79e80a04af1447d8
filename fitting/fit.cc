#include "fitting/fit.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <numbers>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "ceres/ceres.h"
#include <Eigen/Dense>
#include "identification/identify.h"
#include "io/flux_map.h"

namespace fluxcal::fit {
namespace {

constexpr double kPi = std::numbers::pi;

// Residual of one differential-inductance component: (L_model - L_obs)/sigma,
// L_model = d^2 W'/di di (flux_family.h). component: 0 Ldd, 1 Lqq, 2 Ldq.
class InductanceResidual {
 public:
  InductanceResidual(Family f, double id, double iq, int component, double value, double sigma)
      : f_(f), id_(id), iq_(iq), c_(component), v_(value), s_(sigma) {}
  template <typename T>
  bool operator()(const T* const* pp, T* r) const {
    const T* p = pp[0];
    T ldd, lqq, ldq;
    FamilyInductance(f_, T(id_), T(iq_), p, &ldd, &lqq, &ldq);
    const T m = c_ == 0 ? ldd : (c_ == 1 ? lqq : ldq);
    r[0] = (m - v_) / s_;
    return true;
  }
 private:
  Family f_;
  double id_, iq_;
  int c_;
  double v_, s_;
};

// The wrong model a MATLAB script often uses: psi = psi_pm + L_hf i with the
// differential inductance taken as apparent. Only for the comparison test.
class ApparentResidual {
 public:
  ApparentResidual(Family f, double id, double iq, int component, double value, double sigma)
      : f_(f), id_(id), iq_(iq), c_(component), v_(value), s_(sigma) {}
  template <typename T>
  bool operator()(const T* const* pp, T* r) const {
    const T* p = pp[0];
    T pd, pq;
    FamilyFlux(f_, T(id_), T(iq_), p, &pd, &pq);
    T m;
    if (c_ == 0) m = std::abs(id_) > 1e-6 ? (pd - p[0]) / T(id_) : T(v_);
    else if (c_ == 1) m = std::abs(iq_) > 1e-6 ? pq / T(iq_) : T(v_);
    else m = T(v_);
    r[0] = (m - v_) / s_;
    return true;
  }
 private:
  Family f_;
  double id_, iq_;
  int c_;
  double v_, s_;
};

// Steady-state flux linkage component (from voltages at speed).
class FluxResidual {
 public:
  FluxResidual(Family f, double id, double iq, int component, double value, double sigma)
      : f_(f), id_(id), iq_(iq), c_(component), v_(value), s_(sigma) {}
  template <typename T>
  bool operator()(const T* const* pp, T* r) const {
    const T* p = pp[0];
    T pd, pq;
    FamilyFlux(f_, T(id_), T(iq_), p, &pd, &pq);
    r[0] = ((c_ == 0 ? pd : pq) - v_) / s_;
    return true;
  }
 private:
  Family f_;
  double id_, iq_;
  int c_;
  double v_, s_;
};

// Torque T = 1.5 p (psi_d iq - psi_q id) (docs/recording-format.md).
class TorqueResidual {
 public:
  TorqueResidual(Family f, int pp, double id, double iq, double value, double sigma)
      : f_(f), pp_(pp), id_(id), iq_(iq), v_(value), s_(sigma) {}
  template <typename T>
  bool operator()(const T* const* pp, T* r) const {
    const T* p = pp[0];
    T pd, pq;
    FamilyFlux(f_, T(id_), T(iq_), p, &pd, &pq);
    r[0] = (1.5 * pp_ * (pd * iq_ - pq * id_) - v_) / s_;
    return true;
  }
 private:
  Family f_;
  int pp_;
  double id_, iq_, v_, s_;
};

// Prior on psi_pm = p[0].
class PriorResidual {
 public:
  PriorResidual(double v, double s) : v_(v), s_(s) {}
  template <typename T>
  bool operator()(const T* const* pp, T* r) const {
    const T* p = pp[0];
    r[0] = (p[0] - v_) / s_;
    return true;
  }
 private:
  double v_, s_;
};

// Dynamic-size parameter blocks: the number of parameters depends on the
// family, so the functors are wrapped in DynamicAutoDiffCostFunction.
template <typename F>
ceres::CostFunction* Make(F* f, int n) {
  auto* c = new ceres::DynamicAutoDiffCostFunction<F, 8>(f);
  c->AddParameterBlock(n);
  c->SetNumResiduals(1);
  return c;
}

struct Built {
  std::vector<double> params;
  std::unique_ptr<ceres::Problem> problem;
  int residuals = 0;
  bool has_prior = false;
};

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

Built Build(const Family& fam, const FitData& d, const FitOptions& o) {
  Built b;
  b.params = InitialParams(fam, d);
  b.problem = std::make_unique<ceres::Problem>();
  const int n = fam.NumParams();
  double* p = b.params.data();
  auto add = [&](ceres::CostFunction* c, bool robust) {
    b.problem->AddResidualBlock(c, robust ? new ceres::CauchyLoss(o.robust_scale) : nullptr, p);
    ++b.residuals;
  };
  for (const auto& obs : d.inductances) {
    const double sd = std::max(obs.ldd_h_std, o.relative_sigma_floor * std::abs(obs.ldd_h));
    const double sq = std::max(obs.lqq_h_std, o.relative_sigma_floor * std::abs(obs.lqq_h));
    if (o.differential_as_apparent) {
      add(Make(new ApparentResidual(fam, obs.id_a, obs.iq_a, 0, obs.ldd_h, sd), n), true);
      add(Make(new ApparentResidual(fam, obs.id_a, obs.iq_a, 1, obs.lqq_h, sq), n), true);
      continue;
    }
    add(Make(new InductanceResidual(fam, obs.id_a, obs.iq_a, 0, obs.ldd_h, sd), n), true);
    add(Make(new InductanceResidual(fam, obs.id_a, obs.iq_a, 1, obs.lqq_h, sq), n), true);
    if (obs.ldq_h) {
      const double mean = 0.5 * (obs.ldd_h + obs.lqq_h);
      const double sx = std::max(obs.ldq_h_std, o.relative_sigma_floor * mean);
      add(Make(new InductanceResidual(fam, obs.id_a, obs.iq_a, 2, *obs.ldq_h, sx), n), true);
    }
  }
  for (const auto& s : d.steady_state) {
    double pd, pq;
    SteadyStateFlux(s, d.pole_pairs, d.rs_ohm, d.f_pwm_hz, &pd, &pq);
    const double we = std::abs(s.speed_rpm) * d.pole_pairs * 2 * kPi / 60.0;
    // Voltage noise ~0.05 V plus 0.5 % for the nominal Rs and delay model.
    const double sigma = 0.05 / std::max(we, 1.0) + 0.005 * std::hypot(pd, pq);
    add(Make(new FluxResidual(fam, s.id_a, s.iq_a, 0, pd, sigma), n), true);
    add(Make(new FluxResidual(fam, s.id_a, s.iq_a, 1, pq, sigma), n), true);
    if (s.torque_nm) {
      const double st = 0.02 + 0.005 * std::abs(*s.torque_nm);
      add(Make(new TorqueResidual(fam, d.pole_pairs, s.id_a, s.iq_a, *s.torque_nm, st), n), true);
    }
  }
  for (const auto& f : d.fluxes) {
    add(Make(new FluxResidual(fam, f.id_a, f.iq_a, 0, f.psi_d_wb, f.psi_std_wb), n), true);
    add(Make(new FluxResidual(fam, f.id_a, f.iq_a, 1, f.psi_q_wb, f.psi_std_wb), n), true);
  }
  if (d.psi_pm_prior_wb) {
    b.has_prior = true;
    add(Make(new PriorResidual(*d.psi_pm_prior_wb, o.psi_pm_prior_relative_std * *d.psi_pm_prior_wb), n),
        false);
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

struct Solved {
  Family family;
  std::vector<double> params, covariance;
  double chi2 = 0, bic = 0;
  int n_obs = 0, k = 0;
  std::string termination;
  bool usable = false;
};

// The polynomial and spline co-energies are linear in their coefficients, and so is every
// residual above (flux, inductance, torque, prior): r(p) = r0 + J p with J
// constant. Ceres evaluates r0 and J from the same cost functors
// (Problem::Evaluate at p = 0), then iteratively reweighted least squares
// with the Cauchy weights w = 1 / (1 + (r/c)^2) minimises the same robust
// cost as the Ceres solve, in a fraction of the time.
//
// With a roughness penalty P (rows: first differences of the inductance,
// i.e. third derivatives of the co-energy, on a grid over the measured
// region; built by RoughnessPenalty) the normal matrix becomes
// J^T W J + lambda P^T P, and lambda is chosen at every reweighting step by
// generalised cross-validation (Craven & Wahba 1979; Hastie, Tibshirani &
// Friedman, ESL 2nd ed., eq. 7.52):
//   GCV(lambda) = n RSS_w / (n - tr H)^2,  H = J_w (J^T W J + lambda P^T P)^-1 J_w^T,
// so the data, not a constant, decide how smooth the surface is. The
// effective number of parameters tr H replaces k in BIC.
Solved SolveLinear(const Family& fam, Built& b, const FitOptions& o, const Eigen::MatrixXd* penalty = nullptr) {
  Solved s;
  s.family = fam;
  std::fill(b.params.begin(), b.params.end(), 0.0);
  ceres::Problem::EvaluateOptions eo;
  eo.apply_loss_function = false;
  double cost = 0;
  std::vector<double> r0;
  ceres::CRSMatrix crs;
  b.problem->Evaluate(eo, &cost, &r0, nullptr, &crs);
  const int n = crs.num_rows, k = crs.num_cols;
  Eigen::MatrixXd J = Eigen::MatrixXd::Zero(n, k);
  for (int r = 0; r < n; ++r)
    for (int i = crs.rows[r]; i < crs.rows[r + 1]; ++i) J(r, crs.cols[i]) = crs.values[i];
  const Eigen::Map<const Eigen::VectorXd> r0v(r0.data(), n);
  // Which residual rows carry the robust loss: all but the prior (last row
  // when a prior exists; Build adds it last).
  const int robust_rows = n - (b.has_prior ? 1 : 0);
  Eigen::VectorXd p = Eigen::VectorXd::Zero(k), w = Eigen::VectorXd::Ones(n);
  const double c2 = o.robust_scale * o.robust_scale;
  // Minimum-norm solutions (complete orthogonal decomposition): the spline
  // family has parameter directions the surfaces do not depend on
  // (Family::NullDirections); they get zero weight and zero variance.
  // Normal matrix J^T W J as a symmetric rank-n update (half the flops of
  // the general product; it dominates the fit time).
  auto normal = [&](const Eigen::MatrixXd& Jw) {
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(k, k);
    A.selfadjointView<Eigen::Lower>().rankUpdate(Jw.transpose());
    return Eigen::MatrixXd(A.selfadjointView<Eigen::Lower>());
  };
  Eigen::MatrixXd PtP;
  double lambda = 0, dof = 0;
  if (penalty != nullptr) PtP = penalty->transpose() * *penalty;
  // Penalised solve at one lambda: parameters and tr H.
  auto solve_at = [&](const Eigen::MatrixXd& A0, const Eigen::VectorXd& g, double lam, double* trace) {
    Eigen::MatrixXd A = A0;
    if (lam > 0) A += lam * PtP;
    const auto cod = A.completeOrthogonalDecomposition();
    if (trace != nullptr) *trace = cod.solve(A0).trace();
    return Eigen::VectorXd(cod.solve(g));
  };
  for (int it = 0; it < 30; ++it) {
    const Eigen::MatrixXd Jw = w.cwiseSqrt().asDiagonal() * J;
    const Eigen::VectorXd rw = w.cwiseSqrt().asDiagonal() * r0v;
    const Eigen::MatrixXd A = normal(Jw);
    const Eigen::VectorXd g = -Jw.transpose() * rw;
    Eigen::VectorXd np;
    if (penalty != nullptr && it > 5) {
      np = solve_at(A, g, lambda, nullptr);   // lambda settled with the weights
    } else if (penalty != nullptr) {
      // lambda on a log grid relative to the normal matrix's scale, chosen
      // again while the robust weights still move (first iterations).
      const double scale = A.trace() / std::max(1.0, PtP.trace());
      double best = std::numeric_limits<double>::infinity();
      for (int e = 0; e <= 20; ++e) {
        const double lam = scale * std::pow(10.0, -10.0 + 0.6 * e);
        double tr = 0;
        const Eigen::VectorXd q = solve_at(A, g, lam, &tr);
        const double rss = (rw + Jw * q).squaredNorm();
        const double gcv = n * rss / std::pow(std::max(1.0, n - tr), 2);
        if (gcv < best) { best = gcv; lambda = lam; dof = tr; np = q; }
      }
    } else {
      np = fam.NullDirections() > 0 ? Eigen::VectorXd(A.completeOrthogonalDecomposition().solve(g))
                                    : Eigen::VectorXd(A.ldlt().solve(g));
    }
    const double step = (np - p).norm();
    p = np;
    const Eigen::VectorXd r = r0v + J * p;
    for (int i = 0; i < robust_rows; ++i) w(i) = 1.0 / (1.0 + r(i) * r(i) / c2);
    // Weights settle geometrically; 1e-10 of |p| is far below the
    // parameters' standard errors.
    if (step < 1e-10 * (1.0 + p.norm())) break;
  }
  const Eigen::VectorXd r = r0v + J * p;
  double chi2 = 0;
  for (int i = 0; i < n; ++i) chi2 += i < robust_rows ? c2 * std::log1p(r(i) * r(i) / c2) : r(i) * r(i);
  for (int i = 0; i < k; ++i) b.params[i] = p(i);
  s.params = b.params;
  s.chi2 = chi2;
  s.n_obs = b.residuals;
  s.k = k - fam.NullDirections();
  const double k_eff = penalty != nullptr ? dof : s.k;
  s.bic = chi2 + k_eff * std::log(std::max(1, n));
  s.usable = p.allFinite();
  s.termination = penalty != nullptr
                      ? absl::StrFormat("CONVERGENCE (penalised linear IRLS, GCV lambda=%.3g, dof=%.1f)", lambda, dof)
                      : "CONVERGENCE (linear IRLS)";
  const Eigen::MatrixXd Jw = w.cwiseSqrt().asDiagonal() * J;
  Eigen::MatrixXd A = normal(Jw);
  if (penalty != nullptr) A += lambda * PtP;
  const Eigen::MatrixXd cov = fam.NullDirections() > 0 || penalty != nullptr
                                  ? Eigen::MatrixXd(A.completeOrthogonalDecomposition().pseudoInverse())
                                                       : Eigen::MatrixXd(A.ldlt().solve(Eigen::MatrixXd::Identity(k, k)));
  const double scale = std::max(1.0, chi2 / std::max(1.0, n - k_eff));
  s.covariance.assign(k * k, 0.0);
  for (int i = 0; i < k; ++i)
    for (int j = 0; j < k; ++j) s.covariance[i * k + j] = cov(i, j) * scale;
  return s;
}

// Roughness of the differential inductance over the measured region: rows
// (L_c(x_{i+1}) - L_c(x_i)) / (h L_c,typ) for c = dd, qq, dq along id and iq
// on a 16 x 16 grid, each linear in the coefficients (L is the Hessian of a
// co-energy linear in them). First differences of L are third derivatives
// of W: the penalty the smoothing-spline family minimises besides the data.
Eigen::MatrixXd RoughnessPenalty(const Family& fam, const FitData& d, double id_lo, double id_hi, double iq_lo,
                                 double iq_hi) {
  const int k = fam.NumParams(), g = 16;
  double typ[3] = {0, 0, 0};
  for (const auto& obs : d.inductances) {
    typ[0] += std::abs(obs.ldd_h); typ[1] += std::abs(obs.lqq_h);
  }
  const double nobs = std::max<size_t>(1, d.inductances.size());
  typ[0] = std::max(typ[0] / nobs, 1e-9); typ[1] = std::max(typ[1] / nobs, 1e-9);
  typ[2] = 0.5 * (typ[0] + typ[1]);
  // L at every grid node as a linear map of the coefficients: column j is
  // the inductance of unit coefficient vector e_j.
  std::vector<Eigen::MatrixXd> node(g * g, Eigen::MatrixXd::Zero(3, k));
  std::vector<double> e(k, 0.0);
  for (int j = 0; j < k; ++j) {
    e[j] = 1.0;
    for (int a = 0; a < g; ++a) {
      for (int bq = 0; bq < g; ++bq) {
        const double id = id_lo + (id_hi - id_lo) * a / (g - 1), iq = iq_lo + (iq_hi - iq_lo) * bq / (g - 1);
        double l[3];
        FamilyInductance(fam, id, iq, e.data(), &l[0], &l[1], &l[2]);
        for (int c = 0; c < 3; ++c) node[a * g + bq](c, j) = l[c] / typ[c];
      }
    }
    e[j] = 0.0;
  }
  Eigen::MatrixXd P(3 * 2 * g * (g - 1), k);
  int row = 0;
  for (int a = 0; a < g; ++a) {
    for (int bq = 0; bq < g; ++bq) {
      if (a + 1 < g) P.middleRows(row, 3) = node[(a + 1) * g + bq] - node[a * g + bq], row += 3;
      if (bq + 1 < g) P.middleRows(row, 3) = node[a * g + bq + 1] - node[a * g + bq], row += 3;
    }
  }
  return P.topRows(row);
}

Solved Solve(const Family& fam, const FitData& d, const FitOptions& o, const Eigen::MatrixXd* penalty = nullptr) {
  Built b = Build(fam, d, o);
  if (fam.kind != Family::kAnalytic) return SolveLinear(fam, b, o, penalty);
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 200;
  so.function_tolerance = 1e-12;
  so.parameter_tolerance = 1e-12;
  so.gradient_tolerance = 1e-14;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary sum;
  ceres::Solve(so, b.problem.get(), &sum);
  Solved s;
  s.family = fam;
  s.params = b.params;
  s.termination = ceres::TerminationTypeToString(sum.termination_type);
  s.usable = sum.IsSolutionUsable();
  s.chi2 = 2.0 * sum.final_cost;
  s.n_obs = b.residuals;
  s.k = fam.kind == Family::kAnalytic ? fam.NumParams() - 1 : fam.NumParams();
  s.bic = s.chi2 + s.k * std::log(std::max(1, s.n_obs));
  // Parameter covariance (Ceres), scaled by the reduced chi^2 when the fit
  // is worse than the stated sigmas (honest uncertainty).
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = -1;
  ceres::Covariance cov(co);
  std::vector<std::pair<const double*, const double*>> blocks = {{b.params.data(), b.params.data()}};
  const int n = fam.NumParams();
  s.covariance.assign(n * n, 0.0);
  if (cov.Compute(blocks, b.problem.get())) {
    cov.GetCovarianceBlock(b.params.data(), b.params.data(), s.covariance.data());
    const double dof = std::max(1, s.n_obs - s.k);
    const double scale = std::max(1.0, s.chi2 / dof);
    for (auto& c : s.covariance) c *= scale;
  }
  return s;
}

}  // namespace

void SteadyStateFlux(const SteadyStateObservation& s, int pole_pairs, double rs_ohm, double f_pwm_hz,
                     double* psi_d, double* psi_q) {
  const double we = s.speed_rpm * pole_pairs * 2 * kPi / 60.0;
  // steady_state.csv holds the fundamental dq command of a delay-compensated
  // controller (inverse Park at theta + 1.5 w_e Ts); the zero-order hold
  // still scales the fundamental the machine sees by sin(x)/x, x = w_e Ts/2
  // (identification/demod.h, eq. (V1)); 3e-4 at 2000 rpm, 4 pole pairs.
  const double ts = 1.0 / f_pwm_hz, x = 0.5 * we * ts;
  const double g = std::abs(x) < 1e-12 ? 1.0 : std::sin(x) / x;
  const std::complex<double> u = std::complex<double>(s.ud_ref_v, s.uq_ref_v) * g;
  *psi_d = (u.imag() - rs_ohm * s.iq_a) / we;
  *psi_q = -(u.real() - rs_ohm * s.id_a) / we;
}

FitData FitDataFromRecording(const io::RecordingSet& set,
                             const std::vector<ident::HfPointResult>& identified) {
  FitData d = FitDataFromHfRows(&set.manifest, set.hf_results);
  for (const auto& r : identified) {
    if (!r.reliable && r.flags.size() == 1 && r.flags[0] == "clipping") continue;
    if (!std::isfinite(r.ld_h) || !std::isfinite(r.lq_h) || !std::isfinite(r.id_a)) continue;
    InductanceObservation o;
    o.id_a = r.id_a; o.iq_a = r.iq_a;
    o.ldd_h = r.ld_h; o.lqq_h = r.lq_h;
    o.ldd_h_std = r.ld_h_std; o.lqq_h_std = r.lq_h_std;
    if (r.has_ldq) { o.ldq_h = r.ldq_h; o.ldq_h_std = r.ldq_h_std; }
    d.inductances.push_back(o);
  }
  for (const auto& s : set.steady_state) {
    d.steady_state.push_back({s.id_a, s.iq_a, s.speed_rpm, s.ud_ref_v, s.uq_ref_v, s.torque_nm});
  }
  return d;
}

FitData FitDataFromHfRows(const io::Manifest* m, const std::vector<io::HfResultRow>& rows) {
  FitData d;
  if (m) {
    d.serial = m->serial;
    d.pole_pairs = m->motor.pole_pairs;
    d.rs_ohm = m->motor.rs_ohm.value_or(0.0);
    d.f_pwm_hz = m->drive.f_pwm_hz.value_or(m->drive.f_sample_hz);
    d.psi_pm_prior_wb = m->motor.psi_pm_wb;
  }
  for (const auto& r : rows) {
    InductanceObservation o;
    o.id_a = r.id_a; o.iq_a = r.iq_a; o.ldd_h = r.ld_h; o.lqq_h = r.lq_h; o.ldq_h = r.ldq_h;
    d.inductances.push_back(o);
  }
  return d;
}

FitData FitDataFromFluxMap(const io::FluxMap& map, int pole_pairs, double psi_std_wb) {
  FitData d;
  d.pole_pairs = pole_pairs;
  const auto points = map.Points();
  if (!(psi_std_wb > 0)) {
    double scale = 0;
    for (const auto& p : points) scale = std::max(scale, std::hypot(p.psi_d_wb, p.psi_q_wb));
    psi_std_wb = 0.002 * scale;
  }
  for (const auto& p : points) {
    d.fluxes.push_back({p.id_a, p.iq_a, p.psi_d_wb, p.psi_q_wb, psi_std_wb});
    // The prior's sigma is relative to it: only a magnet flux (> 0) is one
    // (a synchronous reluctance map has psi_d(0, 0) = 0).
    if (p.id_a == 0 && p.iq_a == 0 && p.psi_d_wb > 0) d.psi_pm_prior_wb = p.psi_d_wb;
  }
  return d;
}

absl::StatusOr<Calibration> Fit(const FitData& d, const FitOptions& o) {
  if (d.inductances.size() < 3 && d.steady_state.size() < 3 && d.fluxes.size() < 3) {
    return absl::InvalidArgumentError(absl::StrCat(
        "field 'points': need at least 3 identified points to fit, got ", d.inductances.size()));
  }
  for (size_t k = 0; k < d.inductances.size(); ++k) {
    const auto& obs = d.inductances[k];
    if (!(obs.ldd_h > 0) || !(obs.lqq_h > 0) || !std::isfinite(obs.id_a) || !std::isfinite(obs.iq_a)) {
      return absl::InvalidArgumentError(absl::StrCat("points[", k, "]: inductances must be positive and finite"));
    }
  }
  double id_min = std::numeric_limits<double>::max(), id_max = -id_min, iq_min = id_min, iq_max = -id_min;
  for (const auto& obs : d.inductances) {
    id_min = std::min(id_min, obs.id_a); id_max = std::max(id_max, obs.id_a);
    iq_min = std::min(iq_min, std::abs(obs.iq_a)); iq_max = std::max(iq_max, std::abs(obs.iq_a));
  }
  for (const auto& s : d.steady_state) {
    id_min = std::min(id_min, s.id_a); id_max = std::max(id_max, s.id_a);
    iq_min = std::min(iq_min, std::abs(s.iq_a)); iq_max = std::max(iq_max, std::abs(s.iq_a));
  }
  for (const auto& s : d.fluxes) {
    id_min = std::min(id_min, s.id_a); id_max = std::max(id_max, s.id_a);
    iq_min = std::min(iq_min, std::abs(s.iq_a)); iq_max = std::max(iq_max, std::abs(s.iq_a));
  }
  // Spline knots span the measured region (with id = 0, where psi_pm is
  // defined) plus 5 % on each side.
  auto spline = [&](int spans) {
    Family f;
    f.kind = Family::kSpline;
    f.spline.spans = spans;
    const double lo = std::min(id_min, 0.0), hi = std::max(id_max, 0.0);
    const double margin = 0.05 * std::max(hi - lo, 10.0);
    f.spline.id_lo_a = lo - margin;
    f.spline.id_hi_a = hi + margin;
    f.spline.iq_hi_a = 1.05 * std::max(iq_max, 10.0);
    return f;
  };
  auto number_after = [&](const std::string& prefix) {
    try { return std::stoi(o.model.substr(prefix.size())); } catch (...) { return 0; }
  };
  std::vector<Family> candidates;
  if (o.model == "analytic" || o.model == "auto") candidates.push_back({Family::kAnalytic, 0, {}});
  if (o.model == "poly" || o.model == "auto") {
    for (int deg = 3; deg <= 8; ++deg) candidates.push_back({Family::kPoly, deg, {}});
  } else if (o.model.rfind("poly", 0) == 0 && o.model.size() > 4) {
    const int deg = number_after("poly");
    if (deg < 2 || deg > 10) return absl::InvalidArgumentError("flag --model: poly degree must be 2..10");
    candidates.push_back({Family::kPoly, deg, {}});
  }
  if (o.model == "spline" || o.model == "auto") {
    for (int spans = 1; spans <= 4; ++spans) candidates.push_back(spline(spans));
  } else if (o.model.rfind("spline", 0) == 0 && o.model.size() > 6) {
    const int spans = number_after("spline");
    if (spans < 1 || spans > 8) return absl::InvalidArgumentError("flag --model: spline spans must be 1..8");
    candidates.push_back(spline(spans));
  }
  if (candidates.empty() && o.model != "smooth") {
    return absl::InvalidArgumentError(absl::StrCat(
        "flag --model: expected auto, analytic, poly, polyN, spline, splineN or smooth, got '", o.model, "'"));
  }
  // Smoothing splines: many spans, smoothness chosen by GCV (SolveLinear);
  // they may have more coefficients than observations.
  std::vector<bool> smoothing(candidates.size(), false);
  // Not yet in "auto": they cost ~0.2 s (36 points) to ~1 s (2601) more,
  // beyond the fit-time budget (docs/performance.md); opt-in until faster.
  if (o.model == "smooth") {
    for (int spans : {6, 8}) {
      candidates.push_back(spline(spans));
      smoothing.push_back(true);
    }
  }
  std::vector<Solved> solved;
  std::vector<bool> solved_smoothing;
  for (size_t c = 0; c < candidates.size(); ++c) {
    const auto& f = candidates[c];
    if (smoothing[c]) {
      const double lo = std::min(id_min, 0.0), hi = std::max(id_max, 0.0);
      const Eigen::MatrixXd P = RoughnessPenalty(f, d, lo, hi, iq_min, iq_max);
      solved.push_back(Solve(f, d, o, &P));
      solved.back().termination += " smooth";
      solved_smoothing.push_back(true);
      continue;
    }
    // A flexible family needs more observations than parameters.
    if (f.NumParams() + 2 > static_cast<int>(2 * d.inductances.size() + 2 * d.steady_state.size() + 2 * d.fluxes.size())) continue;
    solved.push_back(Solve(f, d, o));
    solved_smoothing.push_back(false);
  }
  if (solved.empty()) return absl::InvalidArgumentError("too few observations for any model family");
  // A candidate must be physical where it was measured: positive-definite
  // inductance over the measured region. (Widening the check by 50 %, as
  // before, vetoed good flexible fits of real machines for their quadratic
  // continuation beyond the knots and kept a 6 % fit of a measured PM-SyRM
  // map instead of a 0.8 % one; queries outside are flagged `extrapolated`.)
  std::vector<bool> physical(solved.size());
  const Solved* best = nullptr;
  for (size_t k = 0; k < solved.size(); ++k) {
    const auto& s = solved[k];
    physical[k] = Calibration(d.serial, s.family, s.params, {}, d.pole_pairs, d.rs_ohm, id_min, id_max,
                              iq_min, iq_max).PhysicalOver(1.0);
    if (s.usable && physical[k] && (best == nullptr || s.bic < best->bic)) best = &s;
  }
  if (best == nullptr) return absl::InternalError("no model family converged to a physical surface");
  Calibration cal(d.serial, best->family, best->params, best->covariance, d.pole_pairs, d.rs_ohm,
                  id_min, id_max, iq_min, iq_max);
  cal.summary.observations = best->n_obs;
  cal.summary.chi2 = best->chi2;
  cal.summary.bic = best->bic;
  cal.summary.termination = best->termination;
  cal.summary.usable = best->usable;
  double rel = 0;
  int nrel = 0;
  for (const auto& obs : d.inductances) {
    const auto L = cal.Inductance(obs.id_a, obs.iq_a);
    rel += std::pow(L.ldd_h / obs.ldd_h - 1, 2) + std::pow(L.lqq_h / obs.lqq_h - 1, 2);
    nrel += 2;
  }
  cal.summary.rms_relative = nrel ? std::sqrt(rel / nrel) : 0.0;
  for (size_t k = 0; k < solved.size(); ++k) {
    const auto& s = solved[k];
    cal.summary.candidates.push_back(absl::StrFormat(
        "%s%s bic=%.2f chi2=%.2f k=%d%s", s.family.Name(), solved_smoothing[k] ? " (smoothing)" : "", s.bic, s.chi2, s.k,
        &s == best ? " (selected)" : (physical[k] ? "" : " (rejected: unphysical extrapolation)")));
  }
  return cal;
}

}  // namespace fluxcal::fit
