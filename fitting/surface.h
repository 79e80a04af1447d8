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

// Roughness of a smoothing-spline co-energy (fit.cc, where it is derived):
// rows of third differences of the coefficients, one column per parameter
// (column 0, psi_pm, is zero). Empty (0 x NumParams) for other families.
Eigen::MatrixXd SmoothingPenalty(const Family& f);

}  // namespace fluxcal::fit

#endif  // FLUXCAL_FITTING_SURFACE_H_
