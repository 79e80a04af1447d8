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

// How far `cal` misses an HF point: the larger of Ldd's and Lqq's
// misfit in sigmas (the stated standard error, at least o's relative
// floor), and its text for the calibration's lists ("ldd_h off the
// surface by -23.1 % (115 sigma").
struct HfPointMisfit {
  double sigmas = 0;
  std::string text;
};
HfPointMisfit MisfitOf(const Calibration& cal, const InductanceObservation& obs, const FitOptions& o);

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_SELECT_H_
