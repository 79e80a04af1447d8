// The linear families' solver (SolveLinear, declared in fitting/solve.h),
// in its steps: the affine residuals as a sparse linear system, the
// roughness penalty's weight lambda by cross-validation (ChooseLambda: the
// Demmler-Reinsch basis, each lambda of a grid scored, the scores ranked),
// the robust reweighting, and the summary of the fit.
//
// The polynomial and spline co-energies are linear in their coefficients, and so is every
// residual above (flux, inductance, torque, prior): r(p) = r0 + J p with J
// constant. Ceres evaluates r0 and J from the same cost functors
// (Problem::Evaluate at p = 0), then iteratively reweighted least squares
// with the Huber weights w = min(1, c / |r|) minimises the same robust
// cost as the Ceres solve, in a fraction of the time (Huber 1981, Robust
// Statistics, sec. 7.8). Weights below 1e-3 are held there: the weights
// cannot all collapse onto a few points.
// Why Huber and not Cauchy: with a roughness penalty the robust objective
// is sum rho(r_i) + lambda |P p|^2, and Cauchy's rho grows only as
// log r^2, so giving up a whole row of consistent points costs less than
// the roughness of the feature they carry. On a twin IPMSM whose Lqq falls
// 10x between iq = 0 and 20 A the Cauchy iteration started from a surface
// through its iq = 0 row (0.87 mH, 1-3 sigma off), bent away a little
// further each step and ended with the row 56 % off and the flux 17 % off
// (RealMaps.TwinTraitMotorsEndToEnd). Huber's rho is convex, the
// penalised objective has one minimum, and a row can only be outvoted by
// data: 2.7 % there; the same lone glitch is still held to a bounded pull
// (Fit.GrossOutlierMovesNothing), and HF results alone on the PM-SyRM
// trait map fit to 0.99 % instead of 5.1 % (docs/fitting.md).
//
// With a roughness penalty P (SmoothingPenalty: third derivatives of the
// co-energy) the normal matrix becomes A + lambda B, A = J^T W J,
// B = P^T P, and lambda is chosen by cross-validation:
//   GCV(lambda) = n RSS_w / (n - tr H)^2,  H = J_w (A + lambda B)^-1 J_w^T
// (Craven & Wahba 1979; Hastie, Tibshirani & Friedman, ESL 2nd ed., eq.
// 7.52), the restricted likelihood choosing between its basins (below).
// Measured against the flux error on maps with known truth
// (tests/fitting/real_maps_test.cc), that beat GCV with inflated degrees of
// freedom (gamma = 1.4), closed-form leave-one-point-out and the restricted
// likelihood alone: on a 6 x 6 bench grid the left-out point is mostly an
// extrapolation, so the first two oversmooth the saturation knee, and the
// flux (the integral of the inductance) is what suffers.
// All lambdas at the price of one eigendecomposition (Demmler-Reinsch
// basis; ESL sec. 5.4.1): with B + eps I = R R^T (Cholesky) and
// R^-1 A R^-T = U D U^T,
//   p(lambda) = R^-T U (D + lambda)^-1 U^T R^-1 g,  tr H = sum d_i / (d_i + lambda).
// H_bb needs only the point's rows of J_w M.
// `acceptable` (penalised fits only): lambdas are tried in order of their
// GCV score until the surface passes it (positive definite where measured):
// GCV now and then picks a near-interpolating lambda that bends the
// inductance negative between two noisy points.
#include <algorithm>
#include <cmath>
#include <vector>

#include "absl/strings/str_format.h"
#include <Eigen/Dense>
#include <Eigen/Sparse>
#include "fitting/solve.h"

namespace fluxcal::fit::internal {
namespace {

// Relative GCV excess accepted for a smoother fit (RankTrials).
constexpr double kGcvTolerance = 0.05;
constexpr double kMinResidualDofShare = 0.10;   // GCV guard: n - tr(H) >= 10 % of n (RankTrials)

// A X = Y for a symmetric positive (semi)definite A: Cholesky, or, when a
// tiny lambda leaves A numerically singular, the minimum-norm solution.
Eigen::MatrixXd SolveSpd(const Eigen::MatrixXd& A, const Eigen::MatrixXd& Y) {
  // A ridge of 1e-12 of the mean diagonal keeps Cholesky alive where a tiny
  // lambda leaves directions only the eps of the penalty holds; it moves
  // nothing the data determine.
  Eigen::MatrixXd Ar = A;
  Ar.diagonal().array() += 1e-12 * A.trace() / std::max<Eigen::Index>(1, A.rows());
  Eigen::LLT<Eigen::MatrixXd> llt(Ar);
  if (llt.info() == Eigen::Success) {
    Eigen::MatrixXd X = llt.solve(Y);
    if (X.allFinite()) return X;
  }
  return A.completeOrthogonalDecomposition().solve(Y);
}

// The residuals r(p) = r0 + J p of a linear family: n rows, k parameters.
class LinearSystem {
 public:
  // From the affine residuals (Build); J sparse: a spline row touches 25 of
  // 100+ coefficients (local support).
  LinearSystem(const Built& b, int k) : n(static_cast<int>(b.linear_rows.size())), k(k), r0(n) {
    std::vector<Eigen::Triplet<double>> nz;
    for (int r = 0; r < n; ++r) {
      r0(r) = b.linear_rows[r].c;
      for (const auto& [j, a] : b.linear_rows[r].t) nz.emplace_back(r, j, a);
    }
    Eigen::SparseMatrix<double> J(n, k);
    J.setFromTriplets(nz.begin(), nz.end());   // sums repeated (folded) entries
    Jr = J;
  }

  // Normal matrix J^T W J = sum_i w_i a_i a_i^T accumulated row by row over
  // each row's nonzeros (nnz^2 per row; a general sparse-sparse product
  // spent most of the fit time on bookkeeping).
  Eigen::MatrixXd Normal(const Eigen::VectorXd& wt) const {
    const int* outer = Jr.outerIndexPtr();
    const int* cols = Jr.innerIndexPtr();
    const double* vals = Jr.valuePtr();
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(k, k);
    double* a = A.data();   // column-major: A(i, j) = a[i + j k]
    for (int r = 0; r < n; ++r) {
      const double wr = wt(r);
      for (int u = outer[r]; u < outer[r + 1]; ++u) {
        const double va = wr * vals[u];
        double* col = a + static_cast<Eigen::Index>(cols[u]) * k;   // column cols[u]
        // Columns are sorted within a row: the lower triangle A(v, u), v >= u.
        for (int v = u; v < outer[r + 1]; ++v) col[cols[v]] += va * vals[v];
      }
    }
    return Eigen::MatrixXd(A.selfadjointView<Eigen::Lower>());
  }

  const int n, k;
  Eigen::VectorXd r0;
  Eigen::SparseMatrix<double, Eigen::RowMajor> Jr;
};

// One lambda of the grid: its GCV score, effective parameters tr H, the
// coefficients, the restricted likelihood (reml, as -2 l_r up to a
// constant) and its rank in the order of preference (RankTrials).
struct Trial { double gcv, lam, tr; Eigen::VectorXd p; int rank = 2; double reml = 0; };

// Every lambda on a log grid around `unit` (the ratio of the two matrices'
// scales; not the largest eigenvalue: the penalty's null space makes that
// one huge), in the Demmler-Reinsch basis (dvals = D, M = R^-T U, z = M^T g,
// JM = J_w M), scored twice: GCV, and the restricted (marginal)
// likelihood of the same penalised fit read as a Gaussian prior on
// the penalised coefficients (Wahba 1985, Ann. Statist. 13(4); Wood
// 2011, JRSS B 73(1)), profiled over the noise variance. In the Demmler-Reinsch
// basis the fit is ridge regression on an orthogonal design
// (J_w M)^T (J_w M) = D, penalty |y|^2, so up to a constant
//   -2 l_r(lambda) = (n - m0) ln(RSS_w + lambda |y|^2)
//                    + sum_{penalised i} ln(1 + d_i / lambda),
// m0 the directions the data see and the penalty does not (their
// d_i carry only the 1/eps of B's regulariser: above 1e7 x `unit`,
// i.e. unpenalised over the whole lambda grid). In lambda order.
std::vector<Trial> ScoreLambdas(const Eigen::VectorXd& dvals, const Eigen::MatrixXd& M, const Eigen::VectorXd& z,
                                const Eigen::MatrixXd& JM, const Eigen::VectorXd& rw, double unit, int n, int k) {
  std::vector<Trial> trials;
  const double d_unpenalised = 1e7 * unit;
  int m0 = 0;
  for (int i = 0; i < k; ++i) m0 += dvals(i) > d_unpenalised;
  for (int e = 0; e <= 56; ++e) {
    const double lam = unit * std::pow(10.0, -10.0 + 0.25 * e);
    const Eigen::VectorXd sv = (dvals.array() + lam).inverse().matrix();
    const Eigen::VectorXd y = z.cwiseProduct(sv);
    const double tr = (dvals.array() * sv.array()).sum();
    const double rss = (rw + JM * y).squaredNorm();
    double log_det = 0;
    for (int i = 0; i < k; ++i) {
      if (dvals(i) <= d_unpenalised) log_det += std::log1p(dvals(i) / lam);
    }
    trials.push_back({n * rss / std::pow(std::max(1.0, n - tr), 2), lam, tr, M * y, 2,
                      (n - m0) * std::log(rss + lam * y.squaredNorm()) + log_det});
  }
  return trials;
}

// Ranks `trials` (in lambda order, as ScoreLambdas returns them) and sorts
// them into the order of preference: (1) the restricted likelihood's
// minimum (among the lambdas that leave enough residual dof, below), from
// there out to the smoothest lambda whose GCV is within kGcvTolerance of
// it (the curve is flat there); (2) the local minima of the GCV curve,
// lowest first: when the surface at (1) is rejected (not positive definite
// where measured), the next candidate is another basin of the curve, not
// the neighbour of the rejected lambda on its own slope; (3) the rest in
// GCV order.
// Why the likelihood: on a 6 x 6 bench grid the GCV curve often has two
// basins, one near interpolation (~120 effective parameters of 136 rows)
// and one smoother (~106), and the first, now and then the lower, follows
// the noise between the measured id columns; the flux, its integral, then
// drifts, and the inductances wiggle between the measured points. GCV
// scores point predictions and cannot see that; the restricted likelihood
// is far less prone to it (Wood 2011, sec. 1; Reiss & Ogden 2009, JRSS B
// 71(2)). With one isotropic weight the likelihood alone once oversmoothed
// a PM-SyRM draw (1.6 %) and an exact coarse map's bridge knee (7.2 %), and
// it only chose among GCV's basins; with the weight per direction
// (SmoothingPenalty's anisotropy, chosen by the same likelihood in
// select.cc) it no longer does, and it decides alone: over 100 bench draws
// of five maps every draw within 0.5 % (two above before), the slope sign
// changes of the fitted inductances a third to a quarter of GCV's
// (docs/fitting.md, "Smoothness chosen by the likelihood").
void RankTrials(std::vector<Trial>& trials, int n) {
  const double best_gcv =
      std::min_element(trials.begin(), trials.end(), [](const Trial& a, const Trial& c) { return a.gcv < c.gcv; })
          ->gcv;
  double tol = (1.0 + kGcvTolerance) * best_gcv;
  std::vector<int> rank(trials.size(), 2);   // trials are in lambda order here
  int basin = -1;   // the restricted likelihood's minimum
  const int nt = static_cast<int>(trials.size());
  auto enough_dof = [&](int i) { return n - trials[i].tr >= kMinResidualDofShare * n; };   // see below
  for (int i = 0; i < nt; ++i) {   // GCV's local minima: the fallbacks (2)
    const bool left = i == 0 || trials[i].gcv <= trials[i - 1].gcv;
    const bool right = i + 1 == nt || trials[i].gcv <= trials[i + 1].gcv;
    if (left && right) rank[i] = 1;
  }
  for (int i = 0; i < nt; ++i) {
    if (enough_dof(i) && (basin < 0 || trials[i].reml < trials[basin].reml)) basin = i;
  }
  if (basin >= 0) {
    tol = (1.0 + kGcvTolerance) * trials[basin].gcv;
    for (int i = basin; i >= 0 && trials[i].gcv <= tol; --i) rank[i] = 0;
    for (int i = basin; i < static_cast<int>(trials.size()) && trials[i].gcv <= tol; ++i) rank[i] = 0;
  } else {
    for (size_t i = 0; i < trials.size(); ++i) {
      if (trials[i].gcv <= tol) rank[i] = 0;
    }
  }
  for (size_t i = 0; i < trials.size(); ++i) trials[i].rank = rank[i];
  // GCV = n RSS / (n - tr)^2 means nothing as tr -> n: on exact or
  // nearly exact data (a flux map, a truth file) its near-interpolation
  // basin wins with RSS ~ 0 and the surface wiggles between the nodes
  // (42 exact flux nodes, 121 coefficients: tr = 0.97 n, the MTPA 7 %
  // off). Such lambdas come last, kept only should nothing else be
  // acceptable: at least 10 % of the observations stay residual dof.
  for (auto& t : trials) {
    if (n - t.tr < kMinResidualDofShare * n) t.rank = 3;
  }
  std::sort(trials.begin(), trials.end(), [&](const Trial& a, const Trial& c) {
    if (a.rank != c.rank) return a.rank < c.rank;
    return a.rank == 0 ? a.lam > c.lam : a.gcv < c.gcv;
  });
}

// The roughness penalty's weight, its effective parameters tr H and the
// coefficients it gives.
struct LambdaChoice {
  double lambda = 0, dof = 0, reml = 0;
  Eigen::VectorXd params;
};

// The first step of a penalised fit: lambda chosen in the Demmler-Reinsch
// basis at unit weights (w: all ones at the first step; A = J^T W J, g =
// -J^T W r0), the first acceptable of the ranked trials (the first of all
// when none is, or without `acceptable`). Lambda is chosen before the
// robust weights exist, so it cannot smooth until every residual is large
// and every weight small (the collapse a robust GCV invites).
LambdaChoice ChooseLambda(const LinearSystem& sys, const Eigen::VectorXd& w, const Eigen::MatrixXd& A,
                          const Eigen::VectorXd& g, const Eigen::MatrixXd& B, const Eigen::LLT<Eigen::MatrixXd>& chol,
                          const Acceptable* acceptable) {
  const int n = sys.n, k = sys.k;
  Eigen::MatrixXd M;        // R^-T U
  Eigen::VectorXd dvals;    // D
  const Eigen::VectorXd rw = w.cwiseSqrt().asDiagonal() * sys.r0;
  const Eigen::MatrixXd Linv = chol.matrixL().solve(Eigen::MatrixXd::Identity(k, k));
  const Eigen::MatrixXd C = Linv * A * Linv.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> es(0.5 * (C + C.transpose()));
  dvals = es.eigenvalues().cwiseMax(0.0);
  M = Linv.transpose() * es.eigenvectors();
  const Eigen::VectorXd z = M.transpose() * g;
  const Eigen::MatrixXd JM = w.cwiseSqrt().asDiagonal() * (sys.Jr * M);
  const double unit = A.trace() / std::max(B.trace(), 1e-300);
  std::vector<Trial> trials = ScoreLambdas(dvals, M, z, JM, rw, unit, n, k);
  RankTrials(trials, n);
  const Trial* pick = &trials.front();
  if (acceptable != nullptr) {
    for (const auto& t : trials) {
      if ((*acceptable)(std::vector<double>(t.p.data(), t.p.data() + k))) { pick = &t; break; }
    }
  }
  LambdaChoice choice;
  choice.lambda = pick->lam;
  choice.dof = pick->tr;
  choice.reml = pick->reml;
  choice.params = pick->p;
  return choice;
}

// Huber weights w = min(1, c / |r|), at least 1e-3, for the robust rows at
// residuals r; c^2 (`c2`) updated first. Outliers are judged against the
// typical misfit, not only the stated sigmas: when no family member can
// follow the data to their 0.2 % (a knee sharper than the knots), every
// point misfits by tens of sigmas and a fixed robust scale would
// down-weight the very points that carry the knee. The scale is the robust
// spread of the residuals (1.4826 MAD, Hampel), never below the stated one.
void UpdateHuberWeights(const Eigen::VectorXd& r, const std::vector<bool>& robust, double robust_scale, double* c2,
                        Eigen::VectorXd* w) {
  const int n = static_cast<int>(r.size());
  {
    std::vector<double> ar;
    for (int i = 0; i < n; ++i)
      if (robust[i]) ar.push_back(std::abs(r(i)));
    if (!ar.empty()) {
      std::nth_element(ar.begin(), ar.begin() + ar.size() / 2, ar.end());
      const double spread = std::max(1.0, 1.4826 * ar[ar.size() / 2]);
      *c2 = std::pow(robust_scale * spread, 2);
    }
  }
  for (int i = 0; i < n; ++i)
    if (robust[i]) (*w)(i) = std::max(1e-3, std::min(1.0, std::sqrt(*c2) / std::max(std::abs(r(i)), 1e-300)));
}

// The Report step of a linear fit at its solution p, weights w and Huber
// scale c^2: the robust cost, the covariance, BIC and the GCV score across
// families. B: the penalty's normal matrix (nullptr: not penalised) at
// weight lambda; `dof` its effective parameters (recomputed here at the
// final weights).
Solved Summarise(const Family& fam, Built& b, const LinearSystem& sys, const Eigen::VectorXd& p,
                 const Eigen::VectorXd& w, double c2, const Eigen::MatrixXd* B, double lambda, double dof) {
  const int n = sys.n, k = sys.k;
  Solved s;
  s.family = fam;
  const Eigen::VectorXd r = sys.r0 + sys.Jr * p;
  double chi2 = 0;
  // Huber's cost: r^2 inside the scale, 2 c |r| - c^2 beyond it.
  const double c = std::sqrt(c2);
  for (int i = 0; i < n; ++i) {
    const double a = std::abs(r(i));
    chi2 += b.robust[i] && a > c ? 2 * c * a - c2 : a * a;
  }
  for (int i = 0; i < k; ++i) b.params[i] = p(i);
  s.params = b.params;
  s.chi2 = chi2;
  s.n_obs = b.residuals;
  s.k = k - fam.NullDirections();
  Eigen::MatrixXd A = sys.Normal(w);
  if (B != nullptr) {
    // Effective parameters at the final weights.
    A += lambda * *B;
    dof = SolveSpd(A, A - lambda * *B).trace();
  }
  const double k_eff = B != nullptr ? dof : s.k;
  s.k_eff = k_eff;
  s.lambda = B != nullptr ? lambda : 0.0;
  s.bic = chi2 + k_eff * std::log(std::max(1, n));
  s.usable = p.allFinite();
  s.termination = B != nullptr
                      ? absl::StrFormat("CONVERGENCE (penalised linear IRLS, CV lambda=%.3g, dof=%.1f)", lambda, dof)
                      : "CONVERGENCE (linear IRLS)";
  const Eigen::MatrixXd cov = B != nullptr ? SolveSpd(A, Eigen::MatrixXd::Identity(k, k))
                              : fam.NullDirections() > 0
                                  ? Eigen::MatrixXd(A.completeOrthogonalDecomposition().pseudoInverse())
                                  : Eigen::MatrixXd(A.ldlt().solve(Eigen::MatrixXd::Identity(k, k)));
  // Generalised cross-validation score at the final weights (the
  // selection criterion across families).
  s.cv = n * (w.cwiseSqrt().asDiagonal() * r).squaredNorm() / std::pow(std::max(1.0, n - k_eff), 2);
  // Inflate by the reduced chi^2 when the fit is worse than the stated
  // sigmas; its residual degrees of freedom n - k_eff are floored at n / 5:
  // a smoothing spline near interpolation (k_eff -> n) would otherwise
  // divide by ~0 and report psi_q +- 0.07 Wb on noise-free points. The
  // posterior covariance (A + lambda B)^-1 of the penalised fit (Wahba,
  // J. R. Stat. Soc. B 45 (1983)) is the rest.
  const double scale = std::max(1.0, chi2 / std::max({1.0, n - k_eff, 0.2 * n}));
  s.covariance.assign(k * k, 0.0);
  for (int i = 0; i < k; ++i)
    for (int j = 0; j < k; ++j) s.covariance[i * k + j] = cov(i, j) * scale;
  return s;
}

}  // namespace

Solved SolveLinear(const Family& fam, Built& b, const FitOptions& o, const Eigen::MatrixXd* penalty,
                   const Acceptable* acceptable) {
  std::fill(b.params.begin(), b.params.end(), 0.0);
  const LinearSystem sys(b, fam.NumParams());
  const int k = sys.k;
  Eigen::VectorXd p = Eigen::VectorXd::Zero(k), w = Eigen::VectorXd::Ones(sys.n);
  double c2 = o.robust_scale * o.robust_scale;
  Eigen::MatrixXd B;
  Eigen::LLT<Eigen::MatrixXd> chol;
  if (penalty != nullptr) {
    B = penalty->transpose() * *penalty;
    // eps I: the directions neither the data nor the penalty see (the
    // spline's constant) get zero coefficients instead of a singular solve.
    const double eps = 1e-9 * B.trace() / k;
    B.diagonal().array() += eps;
    chol.compute(B);
  }
  double lambda = 0, dof = 0, reml = 0;
  for (int it = 0; it < 30; ++it) {
    const Eigen::MatrixXd A = sys.Normal(w);
    const Eigen::VectorXd g = -(sys.Jr.transpose() * w.cwiseProduct(sys.r0));
    Eigen::VectorXd np;
    if (penalty != nullptr) {
      if (it == 0) {
        LambdaChoice choice = ChooseLambda(sys, w, A, g, B, chol, acceptable);
        lambda = choice.lambda;
        dof = choice.dof;
        reml = choice.reml;
        np = choice.params;
      } else {
        np = SolveSpd(A + lambda * B, g);
      }
    } else {
      np = fam.NullDirections() > 0 ? Eigen::VectorXd(A.completeOrthogonalDecomposition().solve(g))
                                    : Eigen::VectorXd(A.ldlt().solve(g));
    }
    const double step = (np - p).norm();
    p = np;
    const Eigen::VectorXd r = sys.r0 + sys.Jr * p;
    UpdateHuberWeights(r, b.robust, o.robust_scale, &c2, &w);
    // Weights settle geometrically; 1e-10 of |p| is far below the
    // parameters' standard errors. The penalised fits (a hundred and more
    // coefficients, ~10 ms per step at 441 points) stop at 1e-7: their
    // lambda already bounds the resolution far coarser than that.
    if (step < (penalty != nullptr ? 1e-7 : 1e-10) * (1.0 + p.norm())) break;
  }
  Solved s = Summarise(fam, b, sys, p, w, c2, penalty != nullptr ? &B : nullptr, lambda, dof);
  s.reml = reml;
  return s;
}

}  // namespace fluxcal::fit::internal
