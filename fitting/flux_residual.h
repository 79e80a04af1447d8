// One flux-linkage component at a known operating point (internal to
// fitting/): a steady-state row's flux from its voltages (SteadyStateFlux)
// or a flux map's node.
#ifndef FLUXCAL_FITTING_FLUX_RESIDUAL_H_
#define FLUXCAL_FITTING_FLUX_RESIDUAL_H_

#include "ceres/ceres.h"
#include "fitting/dynamic_cost.h"
#include "fitting/flux_family.h"

namespace fluxcal::fit::internal {

enum class FluxComponent { kPsiD, kPsiQ };

// r = (psi_model - psi_obs) / sigma, psi_model = dW'/di of the family's
// co-energy at the observation's (id, iq) (flux_family.h).
class FluxResidual {
 public:
  FluxResidual(const Family& family, double id_a, double iq_a, FluxComponent component, double psi_wb,
               double sigma_wb)
      : family_(family), id_a_(id_a), iq_a_(iq_a), component_(component), psi_wb_(psi_wb), sigma_wb_(sigma_wb) {}

  // num_params: family.NumParams(), the size of the one parameter block.
  static ceres::CostFunction* Create(const Family& family, double id_a, double iq_a, FluxComponent component,
                                     double psi_wb, double sigma_wb, int num_params) {
    return DynamicCost(new FluxResidual(family, id_a, iq_a, component, psi_wb, sigma_wb), num_params);
  }

  template <typename T>
  bool operator()(const T* const* parameters, T* residual) const {
    const T* p = parameters[0];
    T psi_d, psi_q;
    FamilyFlux(family_, T(id_a_), T(iq_a_), p, &psi_d, &psi_q);
    residual[0] = ((component_ == FluxComponent::kPsiD ? psi_d : psi_q) - psi_wb_) / sigma_wb_;
    return true;
  }

 private:
  const Family family_;
  const double id_a_, iq_a_;
  const FluxComponent component_;
  const double psi_wb_, sigma_wb_;
};

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_FLUX_RESIDUAL_H_
