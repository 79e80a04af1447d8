// Solve, the second of the fit's steps (Build, Solve, Report; internal to
// fitting/): one candidate family fitted to the screened data, with what
// the selection across families needs (fitting/select.h).
#ifndef FLUXCAL_FITTING_SOLVE_H_
#define FLUXCAL_FITTING_SOLVE_H_

#include <functional>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "fitting/fit.h"
#include "fitting/flux_family.h"
#include "fitting/problem.h"

namespace fluxcal::fit::internal {

// A fitted candidate, modelled on ceres::Solver::Summary: termination and
// whether the solution is usable, plus the covariance of the parameters
// (row-major k x k) and the scores the selection compares.
struct Solved {
  Family family;
  std::vector<double> params, covariance;
  double chi2 = 0, bic = 0, cv = 0, k_eff = 0;
  double lambda = 0;   // smoothing families: the roughness penalty's weight
  double anisotropy_q = 1;   // smoothing families: SmoothingPenalty's kappa (select.cc)
  // Smoothing families: -2 log restricted likelihood of (lambda, penalty)
  // up to a constant common to every penalty with the same null space
  // (solve_linear.cc, ScoreLambdas): the smaller, the better the data
  // support this smoothing.
  double reml = 0;
  int n_obs = 0, k = 0;
  std::string termination;
  bool usable = false;
};

// Whether a penalised fit's surface is acceptable (positive definite where
// measured): SolveLinear tries the lambdas in order until one passes.
using Acceptable = std::function<bool(const std::vector<double>& params)>;

// Build and solve family `fam` on `d`: the analytic family with Ceres
// (bounded Levenberg-Marquardt, Huber loss, covariance by dense SVD), the
// linear families with SolveLinear; `penalty` and `acceptable` only for the
// smoothing splines.
Solved Solve(const Family& fam, const FitData& d, const FitOptions& o, const Eigen::MatrixXd* penalty = nullptr,
             const Acceptable* acceptable = nullptr);

// The linear families' robust least squares (solve_linear.cc, where the
// method is derived): iteratively reweighted least squares with Huber
// weights over the affine residuals of `b`, and with a roughness `penalty`
// its weight lambda by cross-validation. Sets b.params.
Solved SolveLinear(const Family& fam, Built& b, const FitOptions& o, const Eigen::MatrixXd* penalty = nullptr,
                   const Acceptable* acceptable = nullptr);

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_SOLVE_H_
