// What the residuals of one observation at an operating point share
// (internal to fitting/): the family, the observation's (id, iq), the
// observed value with its sigma, and r = (model - observed) / sigma.
#ifndef FLUXCAL_FITTING_POINT_RESIDUAL_H_
#define FLUXCAL_FITTING_POINT_RESIDUAL_H_

#include "fitting/flux_family.h"

namespace fluxcal::fit::internal {

// The members and the normalisation, for a residual that models the
// observation its own way (InductanceResidual: the family's inductances or
// the HF orbit's describing function).
class PointObservation {
 protected:
  PointObservation(const Family& family, double id_a, double iq_a, double observed, double sigma)
      : family_(family), id_a_(id_a), iq_a_(iq_a), observed_(observed), sigma_(sigma) {}

  template <typename T>
  T Normalized(const T& model) const {
    return (model - observed_) / sigma_;
  }

  const Family family_;
  const double id_a_, iq_a_;
  // In the residual's unit (Wb, N m, H), as its sigma.
  const double observed_, sigma_;
};

// A residual whose model is a function of the family's flux linkage at the
// observation's (id, iq): Derived::Model(p, psi_d, psi_q) says what the
// observation should have been; the flux and the normalisation are here.
template <typename Derived>
class FluxPointResidual : public PointObservation {
 public:
  template <typename T>
  bool operator()(const T* const* parameters, T* residual) const {
    const T* p = parameters[0];
    T psi_d, psi_q;
    FamilyFlux(family_, T(id_a_), T(iq_a_), p, &psi_d, &psi_q);
    residual[0] = Normalized<T>(static_cast<const Derived&>(*this).Model(p, psi_d, psi_q));
    return true;
  }

 protected:
  using PointObservation::PointObservation;
};

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_POINT_RESIDUAL_H_
