// One differential-inductance component of an HF point (internal to
// fitting/, used by the problem Build assembles).
#ifndef FLUXCAL_FITTING_INDUCTANCE_RESIDUAL_H_
#define FLUXCAL_FITTING_INDUCTANCE_RESIDUAL_H_

#include "ceres/ceres.h"
#include "fitting/dynamic_cost.h"
#include "fitting/flux_family.h"

namespace fluxcal::fit::internal {

enum class InductanceComponent { kLdd, kLqq, kLdq };

// r = (L_model - L_obs) / sigma, L_model = d^2 W' / di di of the family's
// co-energy at the observation's (id, iq) (flux_family.h): Ldd = dpsi_d/did,
// Lqq = dpsi_q/diq, Ldq = dpsi_d/diq = dpsi_q/did. The HF injection measures
// the differential inductance (docs/fitting.md), not psi / i.
class InductanceResidual {
 public:
  InductanceResidual(const Family& family, double id_a, double iq_a, InductanceComponent component,
                     double inductance_h, double sigma_h)
      : family_(family), id_a_(id_a), iq_a_(iq_a), component_(component), inductance_h_(inductance_h),
        sigma_h_(sigma_h) {}

  // num_params: family.NumParams(), the size of the one parameter block.
  static ceres::CostFunction* Create(const Family& family, double id_a, double iq_a, InductanceComponent component,
                                     double inductance_h, double sigma_h, int num_params) {
    return DynamicCost(new InductanceResidual(family, id_a, iq_a, component, inductance_h, sigma_h), num_params);
  }

  template <typename T>
  bool operator()(const T* const* parameters, T* residual) const {
    const T* p = parameters[0];
    T ldd, lqq, ldq;
    FamilyInductance(family_, T(id_a_), T(iq_a_), p, &ldd, &lqq, &ldq);
    const T model =
        component_ == InductanceComponent::kLdd ? ldd : (component_ == InductanceComponent::kLqq ? lqq : ldq);
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

#endif  // FLUXCAL_FITTING_INDUCTANCE_RESIDUAL_H_
