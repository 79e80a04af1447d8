// The wrong model, for the comparison test only (FitOptions::
// differential_as_apparent; internal to fitting/).
#ifndef FLUXCAL_FITTING_APPARENT_RESIDUAL_H_
#define FLUXCAL_FITTING_APPARENT_RESIDUAL_H_

#include <cmath>

#include "ceres/ceres.h"
#include "fitting/dynamic_cost.h"
#include "fitting/flux_family.h"
#include "fitting/inductance_residual.h"

namespace fluxcal::fit::internal {

// The model a MATLAB script often uses: psi = psi_pm + L_hf i, the
// differential inductance taken as apparent:
//   Ldd: r = ((psi_d - psi_pm) / id - L_obs) / sigma   (|id| > 1e-6 A),
//   Lqq: r = (psi_q / iq - L_obs) / sigma              (|iq| > 1e-6 A),
// and 0 otherwise (Ldq, or a current of zero). psi_pm is parameter 0.
class ApparentResidual {
 public:
  ApparentResidual(const Family& family, double id_a, double iq_a, InductanceComponent component,
                   double inductance_h, double sigma_h)
      : family_(family), id_a_(id_a), iq_a_(iq_a), component_(component), inductance_h_(inductance_h),
        sigma_h_(sigma_h) {}

  // num_params: family.NumParams(), the size of the one parameter block.
  static ceres::CostFunction* Create(const Family& family, double id_a, double iq_a, InductanceComponent component,
                                     double inductance_h, double sigma_h, int num_params) {
    return DynamicCost(new ApparentResidual(family, id_a, iq_a, component, inductance_h, sigma_h), num_params);
  }

  template <typename T>
  bool operator()(const T* const* parameters, T* residual) const {
    const T* p = parameters[0];
    T psi_d, psi_q;
    FamilyFlux(family_, T(id_a_), T(iq_a_), p, &psi_d, &psi_q);
    T model;
    if (component_ == InductanceComponent::kLdd) {
      model = std::abs(id_a_) > 1e-6 ? (psi_d - p[0]) / T(id_a_) : T(inductance_h_);
    } else if (component_ == InductanceComponent::kLqq) {
      model = std::abs(iq_a_) > 1e-6 ? psi_q / T(iq_a_) : T(inductance_h_);
    } else {
      model = T(inductance_h_);
    }
    residual[0] = (model - inductance_h_) / sigma_h_;
    return true;
  }

 private:
  const Family family_;
  const double id_a_, iq_a_;
  const InductanceComponent component_;
  const double inductance_h_, sigma_h_;
};

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_APPARENT_RESIDUAL_H_
