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

// A rippled steady-state row (SteadyStateObservation::current_ripple_a).
// Its voltages average the flux over the current's excursion, and for a
// ripple of RMS sigma_i about the mean current i the average differs from
// the flux at i by the second-order term of the Taylor expansion (the
// second-order delta method, Casella & Berger, Statistical Inference, 2nd
// ed., 2002, sec. 5.5.4; the bias term of a random-input describing
// function, Gelb & Vander Velde, Multiple-Input Describing Functions, 1968):
//   E[psi(i + e)] - psi(i) ~ 1/2 psi''(i) sigma_i^2.
// The fit does not know psi''; a saturating characteristic bounds it by its
// flux and current, |psi''| i^2 / |psi| <= kappa (for psi = a tanh(i/I_s)
// the ratio is 2 x^2 sech^2 x <= 0.88, x = i / I_s; kRippleCurvature = 1).
// So the row's flux carries, in quadrature with RowFluxSigmaWb,
//   sigma_ripple = 1/2 kappa r^2 |psi|,  r = sigma_i / max(|i|, i_floor),
// in proportion to the ripple's variance. i_floor is kRippleCurrentFloor of
// the data's largest current (DataCurrentScaleA): a row near zero current
// sits below every saturation knee, its curvature scale is the machine's
// current range, not its own (near-zero) current.
inline constexpr double kRippleCurvature = 1.0;
inline constexpr double kRippleCurrentFloor = 0.1;
// The largest |i| of the HF points and flux nodes (of the rows when there
// are none), A.
double DataCurrentScaleA(const FitData& d);
// r above: the row's ripple relative to its current (0 when not reported).
double RowRelativeRipple(const SteadyStateObservation& s, double current_scale_a);
// A steady-state row's flux sigma: RowFluxSigmaWb and sigma_ripple in
// quadrature.
double RowSigmaWb(const SteadyStateObservation& s, int pole_pairs, double current_scale_a, double psi_d_wb,
                  double psi_q_wb);

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_PROBLEM_H_
