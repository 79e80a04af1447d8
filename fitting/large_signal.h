// Large-signal HF (internal to fitting/; docs/fitting.md, "Large-signal
// HF"): the orbits of the HF points whose injection is known, computed on a
// first pass's surfaces, so that the second pass predicts each point as the
// injection measures it (physics/hf_orbit.h, inductance_residual.h).
#ifndef FLUXCAL_FITTING_LARGE_SIGNAL_H_
#define FLUXCAL_FITTING_LARGE_SIGNAL_H_

#include "fitting/calibration.h"
#include "fitting/fit.h"

namespace fluxcal::fit::internal {

// A point whose describing function differs from its small-signal value by
// less than this share of its standard deviation (on `first`'s surfaces,
// every component) keeps the small-signal model: the second pass would
// not move the fit.
inline constexpr double kLargeSignalMaterialSigma = 0.1;
// Fit keeps the large-signal fit when its cross-validation score is lower
// than the small-signal fit's by more than this share (fit.cc says why),
// or when the orbits change the first pass's predictions by more than
// this many standard deviations at most points (the median).
inline constexpr double kLargeSignalScoreMargin = 0.05;
inline constexpr double kLargeSignalEvidentSigma = 1.0;

// Sets hf_orbit on every inductance observation of `d` with a flux radius
// whose orbit on `first` exists (the surfaces invertible along it), stays
// within the size of the data's region (first order: rho over the smaller
// eigenvalue of L, at most the largest |i| of the points) and matters
// (kLargeSignalMaterialSigma); returns how many. `sigma_floor`: the
// fit's relative floor on inductance sigmas (FitOptions). `median_sigmas`
// (optional): over every orbit solved, the median of its largest change
// (describing function less Jacobian, per component over its sigma).
int AttachHfOrbits(const Calibration& first, double sigma_floor, FitData* d, double* median_sigmas = nullptr);

// What `cal` predicts for the observation: the describing function over its
// orbit where it has one, else the Jacobian at its mean current (the
// residuals' own model, for the fit's report).
sim::DifferentialInductance PredictedInductance(const Calibration& cal, const InductanceObservation& obs);

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_LARGE_SIGNAL_H_
