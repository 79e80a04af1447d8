// The torque a steady-state row's transducer measured (internal to
// fitting/).
#ifndef FLUXCAL_FITTING_TORQUE_RESIDUAL_H_
#define FLUXCAL_FITTING_TORQUE_RESIDUAL_H_

#include "fitting/point_residual.h"
#include "physics/torque.h"

namespace fluxcal::fit::internal {

// r = (T_model - T_obs) / sigma, T_model = 1.5 p (psi_d iq - psi_q id)
// (physics/torque.h, docs/recording-format.md) with the family's flux
// linkage at the row's (id, iq).
class TorqueResidual : public FluxPointResidual<TorqueResidual> {
 public:
  TorqueResidual(const Family& family, int pole_pairs, double id_a, double iq_a, double torque_nm, double sigma_nm)
      : FluxPointResidual(family, id_a, iq_a, torque_nm, sigma_nm), pole_pairs_(pole_pairs) {}

  template <typename T>
  T Model(const T* /*p*/, const T& psi_d, const T& psi_q) const {
    return physics::ElectromagneticTorque(pole_pairs_, psi_d, psi_q, id_a_, iq_a_);
  }

 private:
  const int pole_pairs_;
};

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_TORQUE_RESIDUAL_H_
