// Build, the first of the fit's steps (Build, Solve, Report; internal to
// fitting/): one residual per observation component, whitened by its
// standard deviation, for one candidate family.
#ifndef FLUXCAL_FITTING_PROBLEM_H_
#define FLUXCAL_FITTING_PROBLEM_H_

#include <memory>
#include <vector>

#include "ceres/ceres.h"
#include "fitting/affine.h"
#include "fitting/fit.h"
#include "fitting/flux_family.h"

namespace fluxcal::fit::internal {

// The residuals of one family. The analytic family's go to a Ceres problem
// (bounded parameters, nonlinear); the linear families' (polynomial,
// spline) are each evaluated once as an affine form of the parameters
// (fitting/affine.h) and solved by SolveLinear.
struct Built {
  std::vector<double> params;
  std::unique_ptr<ceres::Problem> problem;   // analytic family only
  int residuals = 0;
  bool has_prior = false;
  // Linear families: every residual as an affine form of the parameters
  // (same functors, T = Affine), and whether it carries the robust loss.
  std::vector<affine::Affine> linear_rows;
  std::vector<bool> robust;
};

// Residuals of `d` for family `fam`: per HF point Ldd, Lqq (and Ldq when
// measured; ApparentResidual instead with o.differential_as_apparent), per
// steady-state row psi_d, psi_q (and torque when measured), per flux node
// psi_d, psi_q, all with the robust loss; the psi_pm prior without it.
Built Build(const Family& fam, const FitData& d, const FitOptions& o);

// Standard deviations of a steady-state row's flux (from its voltages) and
// torque: voltage noise ~0.05 V plus 0.5 % for the nominal Rs and delay
// model; a torque transducer's 0.02 N m plus 0.5 %.
double RowFluxSigmaWb(double speed_rpm, int pole_pairs, double psi_d_wb, double psi_q_wb);
double RowTorqueSigmaNm(double torque_nm);

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_PROBLEM_H_
