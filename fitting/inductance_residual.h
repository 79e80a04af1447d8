// One differential-inductance component of an HF point (internal to
// fitting/, used by the problem Build assembles).
#ifndef FLUXCAL_FITTING_INDUCTANCE_RESIDUAL_H_
#define FLUXCAL_FITTING_INDUCTANCE_RESIDUAL_H_

#include <array>
#include <memory>
#include <vector>

#include "fitting/fit.h"
#include "fitting/flux_family.h"
#include "fitting/point_residual.h"

namespace fluxcal::fit {

// The HF orbit of an observation (physics/hf_orbit.h): the currents along
// the injection's flux circle and the describing function's weights, so
// that (Ldd, Lqq, Ldq)[c] = sum_k weights[c][k] . psi(currents_a[k]).
struct HfOrbitWeights {
  std::vector<std::array<double, 2>> currents_a;
  std::array<std::vector<std::array<double, 2>>, 3> weights;
};

}  // namespace fluxcal::fit

namespace fluxcal::fit::internal {

enum class InductanceComponent { kLdd, kLqq, kLdq };

// r = (L_model - L_obs) / sigma, L_model = d^2 W' / di di of the family's
// co-energy at the observation's (id, iq) (flux_family.h): Ldd = dpsi_d/did,
// Lqq = dpsi_q/diq, Ldq = dpsi_d/diq = dpsi_q/did. The HF injection measures
// the differential inductance (docs/fitting.md), not psi / i.
// With the observation's HF orbit (`orbit`, set where the injection's flux
// radius is known), L_model is what the injection measures on the family's
// surfaces: the describing function over the orbit,
//   L_model[c] = sum_k W_k[c] . psi(i_k)   (physics/hf_orbit.h),
// still linear in the family's coefficients.
class InductanceResidual : public PointObservation {
 public:
  InductanceResidual(const Family& family, double id_a, double iq_a, InductanceComponent component,
                     double inductance_h, double sigma_h, std::shared_ptr<const HfOrbitWeights> orbit = nullptr)
      : PointObservation(family, id_a, iq_a, inductance_h, sigma_h), component_(component), orbit_(std::move(orbit)) {}

  template <typename T>
  bool operator()(const T* const* parameters, T* residual) const {
    const T* p = parameters[0];
    if (orbit_) {
      const auto& w = orbit_->weights[static_cast<int>(component_)];
      T model(0.0);
      for (size_t k = 0; k < orbit_->currents_a.size(); ++k) {
        T psi_d, psi_q;
        FamilyFlux(family_, T(orbit_->currents_a[k][0]), T(orbit_->currents_a[k][1]), p, &psi_d, &psi_q);
        model += psi_d * w[k][0] + psi_q * w[k][1];
      }
      residual[0] = Normalized(model);
      return true;
    }
    T ldd, lqq, ldq;
    FamilyInductance(family_, T(id_a_), T(iq_a_), p, &ldd, &lqq, &ldq);
    const T model =
        component_ == InductanceComponent::kLdd ? ldd : (component_ == InductanceComponent::kLqq ? lqq : ldq);
    residual[0] = Normalized(model);
    return true;
  }

 private:
  const InductanceComponent component_;
  const std::shared_ptr<const HfOrbitWeights> orbit_;
};

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_INDUCTANCE_RESIDUAL_H_
