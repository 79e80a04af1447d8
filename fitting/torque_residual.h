// The torque a steady-state row's transducer measured (internal to
// fitting/).
#ifndef FLUXCAL_FITTING_TORQUE_RESIDUAL_H_
#define FLUXCAL_FITTING_TORQUE_RESIDUAL_H_

#include "ceres/ceres.h"
#include "fitting/dynamic_cost.h"
#include "fitting/flux_family.h"
#include "physics/torque.h"

namespace fluxcal::fit::internal {

// r = (T_model - T_obs) / sigma, T_model = 1.5 p (psi_d iq - psi_q id)
// (physics/torque.h, docs/recording-format.md) with the family's flux
// linkage at the row's (id, iq).
class TorqueResidual {
 public:
  TorqueResidual(const Family& family, int pole_pairs, double id_a, double iq_a, double torque_nm, double sigma_nm)
      : family_(family), pole_pairs_(pole_pairs), id_a_(id_a), iq_a_(iq_a), torque_nm_(torque_nm),
        sigma_nm_(sigma_nm) {}

  // num_params: family.NumParams(), the size of the one parameter block.
  static ceres::CostFunction* Create(const Family& family, int pole_pairs, double id_a, double iq_a,
                                     double torque_nm, double sigma_nm, int num_params) {
    return DynamicCost(new TorqueResidual(family, pole_pairs, id_a, iq_a, torque_nm, sigma_nm), num_params);
  }

  template <typename T>
  bool operator()(const T* const* parameters, T* residual) const {
    const T* p = parameters[0];
    T psi_d, psi_q;
    FamilyFlux(family_, T(id_a_), T(iq_a_), p, &psi_d, &psi_q);
    residual[0] = (physics::ElectromagneticTorque(pole_pairs_, psi_d, psi_q, id_a_, iq_a_) - torque_nm_) / sigma_nm_;
    return true;
  }

 private:
  const Family family_;
  const int pole_pairs_;
  const double id_a_, iq_a_, torque_nm_, sigma_nm_;
};

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_TORQUE_RESIDUAL_H_
