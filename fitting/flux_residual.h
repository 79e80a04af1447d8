// One flux-linkage component at a known operating point (internal to
// fitting/): a steady-state row's flux from its voltages (SteadyStateFlux)
// or a flux map's node.
#ifndef FLUXCAL_FITTING_FLUX_RESIDUAL_H_
#define FLUXCAL_FITTING_FLUX_RESIDUAL_H_

#include "fitting/point_residual.h"

namespace fluxcal::fit::internal {

enum class FluxComponent { kPsiD, kPsiQ };

// r = (psi_model - psi_obs) / sigma, psi_model = dW'/di of the family's
// co-energy at the observation's (id, iq) (flux_family.h).
class FluxResidual : public FluxPointResidual<FluxResidual> {
 public:
  FluxResidual(const Family& family, double id_a, double iq_a, FluxComponent component, double psi_wb,
               double sigma_wb)
      : FluxPointResidual(family, id_a, iq_a, psi_wb, sigma_wb), component_(component) {}

  template <typename T>
  T Model(const T* /*p*/, const T& psi_d, const T& psi_q) const {
    return component_ == FluxComponent::kPsiD ? psi_d : psi_q;
  }

 private:
  const FluxComponent component_;
};

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_FLUX_RESIDUAL_H_
