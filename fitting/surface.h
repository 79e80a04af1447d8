// A family's surfaces at one operating point with their derivatives with
// respect to the family's parameters, and the roughness penalty of the
// smoothing splines: what a fit that carries the flux-linkage surfaces as
// unknowns beside other parameters (diagnosis/refit.cc) differentiates
// through, and the penalty it keeps them smooth with.
#ifndef FLUXCAL_FITTING_SURFACE_H_
#define FLUXCAL_FITTING_SURFACE_H_

#include <array>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "fitting/flux_family.h"

namespace fluxcal::fit {

// Values at (id_a, iq_a), in the order kSurfaceValues names them, and
// their sparse gradient: d value / d params[index]. Linear families (poly,
// spline): exact (a spline point touches the 25 coefficients around it and
// the 25 around the origin that fix psi_d(0, 0) = psi_pm); the analytic
// family: forward-mode automatic differentiation (ceres::Jet).
enum SurfaceValue { kPsiD = 0, kPsiQ = 1, kLdd = 2, kLqq = 3, kLdq = 4, kSurfaceValues = 5 };
struct SurfacePoint {
  std::array<double, kSurfaceValues> value{};
  std::vector<std::pair<int, std::array<double, kSurfaceValues>>> grad;
};
SurfacePoint SurfaceAt(const Family& f, const double* params, double id_a, double iq_a);

// A family's surfaces for fixed parameters, evaluated at many points (a
// replay's Newton steps): the spline family through SplineSurface
// (flux_family.h, its one fast evaluation: the coefficient grid and the
// origin's terms set up once), the others through FamilyFlux and
// FamilyInductance. Null pointers skip an output.
class SurfaceEvaluator {
 public:
  SurfaceEvaluator() = default;
  SurfaceEvaluator(const Family& f, std::vector<double> params);
  void Eval(double id_a, double iq_a, double* psi_d, double* psi_q, double* ldd, double* lqq, double* ldq) const;

 private:
  Family f_;
  std::vector<double> p_;
  SplineSurface spline_;
};

// Roughness of a smoothing-spline co-energy (surface.cc, where it is derived):
// rows of third differences of the coefficients (the inductance's slopes)
// and, weighted by `curvature_weight`, of fourth differences (the
// inductance's curvature, all but Lqq's along iq), one column per
// parameter (column 0, psi_pm, is zero). Empty (0 x NumParams) for other
// families.
// `anisotropy_q` (kappa > 0) weighs bending along iq against bending along
// id: the squared term of W_{d^a q^b} carries kappa^((b - a)/6), so W_qqq^2
// counts kappa times as much as W_ddd^2 (1: isotropic in amperes).
// `curvature_weight`: 0 is the penalty of calibrations written before
// fit.smoothing_curvature_weight existed (third derivatives only); new fits
// use kSmoothingCurvatureWeight.
Eigen::MatrixXd SmoothingPenalty(const Family& f, double anisotropy_q = 1.0, double curvature_weight = 0.0);

// The curvature term's weight of new fits (surface.cc says why 1).
inline constexpr double kSmoothingCurvatureWeight = 1.0;

}  // namespace fluxcal::fit

#endif  // FLUXCAL_FITTING_SURFACE_H_
