// The fit of screened data (internal to fitting/): every candidate family
// the model name allows, solved (fitting/solve.h), the physical one with
// the lowest cross-validation score kept and reported.
#ifndef FLUXCAL_FITTING_SELECT_H_
#define FLUXCAL_FITTING_SELECT_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "fitting/fit.h"

namespace fluxcal::fit::internal {

// `excluded` lists what the screen left out; the down-weighted points are
// added to it in the calibration's summary (and counted in
// *down_weighted). `not_pd`: the cells where the surface need not be
// positive definite (Screen). Errors: InvalidArgument (fewer than 3 usable
// observations of every kind, a model name ParseModelName refuses, too few
// observations for any family), Cancelled (o.cancelled), Internal (no
// family converged to a physical surface). *selected_cv: the kept family's
// cross-validation score (what Fit compares the HF forward models by).
absl::StatusOr<Calibration> FitScreened(const FitData& d, std::vector<std::string> excluded,
                                        const std::vector<Calibration::Box>& not_pd, const FitOptions& o,
                                        int* down_weighted = nullptr, double* selected_cv = nullptr);

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_SELECT_H_
