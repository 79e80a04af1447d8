// The magnet flux the data source states, as a prior (internal to
// fitting/).
#ifndef FLUXCAL_FITTING_PRIOR_RESIDUAL_H_
#define FLUXCAL_FITTING_PRIOR_RESIDUAL_H_

namespace fluxcal::fit::internal {

// r = (psi_pm - psi_pm_prior) / sigma, psi_pm parameter 0 of every family
// (flux_family.h: psi_d(0, 0) = psi_pm).
class PriorResidual {
 public:
  PriorResidual(double psi_pm_wb, double sigma_wb) : psi_pm_wb_(psi_pm_wb), sigma_wb_(sigma_wb) {}

  template <typename T>
  bool operator()(const T* const* parameters, T* residual) const {
    const T* p = parameters[0];
    residual[0] = (p[0] - psi_pm_wb_) / sigma_wb_;
    return true;
  }

 private:
  const double psi_pm_wb_, sigma_wb_;
};

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_PRIOR_RESIDUAL_H_
