// The Ceres cost function of one fit residual (internal to fitting/): the
// problem's residual sink wraps every residual functor with this. The number of parameters depends
// on the family (7 analytic, up to ~150 spline coefficients), so the
// functors are wrapped in a DynamicAutoDiffCostFunction with one parameter
// block of that size and one residual.
#ifndef FLUXCAL_FITTING_DYNAMIC_COST_H_
#define FLUXCAL_FITTING_DYNAMIC_COST_H_

#include "ceres/ceres.h"

namespace fluxcal::fit::internal {

// Takes ownership of `functor`.
template <typename F>
ceres::CostFunction* DynamicCost(F* functor, int num_params) {
  auto* cost = new ceres::DynamicAutoDiffCostFunction<F, 8>(functor);
  cost->AddParameterBlock(num_params);
  cost->SetNumResiduals(1);
  return cost;
}

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_DYNAMIC_COST_H_
