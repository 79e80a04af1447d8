#include "fitting/solve.h"

#include <algorithm>
#include <cmath>
#include <utility>

#include "ceres/ceres.h"

namespace fluxcal::fit::internal {

Solved Solve(const Family& fam, const FitData& d, const FitOptions& o, const Eigen::MatrixXd* penalty,
             const Acceptable* acceptable) {
  Built b = Build(fam, d, o);
  if (fam.kind != Family::kAnalytic) return SolveLinear(fam, b, o, penalty, acceptable);
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
  s.k_eff = s.k;
  // Parameter covariance (Ceres), scaled by the reduced chi^2 when the fit
  // is worse than the stated sigmas (honest uncertainty).
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = -1;
  ceres::Covariance cov(co);
  std::vector<std::pair<const double*, const double*>> blocks = {{b.params.data(), b.params.data()}};
  const int n = fam.NumParams();
  s.covariance.assign(n * n, 0.0);
  // Only at a finite, usable solution: Ceres' dense SVD is not defended
  // against non-finite Jacobians.
  if (s.usable && std::isfinite(s.chi2) && cov.Compute(blocks, b.problem.get())) {
    cov.GetCovarianceBlock(b.params.data(), b.params.data(), s.covariance.data());
    const double dof = std::max(1, s.n_obs - s.k);
    const double scale = std::max(1.0, s.chi2 / dof);
    for (auto& c : s.covariance) c *= scale;
  }
  // Generalised cross-validation score with k parameters (chi2 is the
  // robust cost, the IRLS-weighted residual sum at the solution).
  s.cv = s.n_obs * s.chi2 / std::pow(std::max(1.0, double(s.n_obs - s.k)), 2);
  return s;
}

}  // namespace fluxcal::fit::internal
