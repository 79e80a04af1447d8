// The wrong model, for the comparison test only (FitOptions::
// differential_as_apparent; internal to fitting/).
#ifndef FLUXCAL_FITTING_APPARENT_RESIDUAL_H_
#define FLUXCAL_FITTING_APPARENT_RESIDUAL_H_

#include <cmath>

#include "fitting/inductance_residual.h"
#include "fitting/point_residual.h"

namespace fluxcal::fit::internal {

// The model a MATLAB script often uses: psi = psi_pm + L_hf i, the
// differential inductance taken as apparent:
//   Ldd: r = ((psi_d - psi_pm) / id - L_obs) / sigma   (|id| > 1e-6 A),
//   Lqq: r = (psi_q / iq - L_obs) / sigma              (|iq| > 1e-6 A),
// and 0 otherwise (Ldq, or a current of zero). psi_pm is parameter 0.
class ApparentResidual : public FluxPointResidual<ApparentResidual> {
 public:
  ApparentResidual(const Family& family, double id_a, double iq_a, InductanceComponent component,
                   double inductance_h, double sigma_h)
      : FluxPointResidual(family, id_a, iq_a, inductance_h, sigma_h), component_(component) {}

  // observed_: the inductance, H.
  template <typename T>
  T Model(const T* p, const T& psi_d, const T& psi_q) const {
    T model;
    if (component_ == InductanceComponent::kLdd) {
      model = std::abs(id_a_) > 1e-6 ? (psi_d - p[0]) / T(id_a_) : T(observed_);
    } else if (component_ == InductanceComponent::kLqq) {
      model = std::abs(iq_a_) > 1e-6 ? psi_q / T(iq_a_) : T(observed_);
    } else {
      model = T(observed_);
    }
    return model;
  }

 private:
  const InductanceComponent component_;
};

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_APPARENT_RESIDUAL_H_
