// The row screens (internal to fitting/): what cannot be an observation of
// a physical machine, and the steady-state rows that did not hold their
// operating point, left out of the fit with their reasons.
#ifndef FLUXCAL_FITTING_SCREEN_H_
#define FLUXCAL_FITTING_SCREEN_H_

#include <string>
#include <vector>

#include "fitting/calibration.h"
#include "fitting/fit.h"

namespace fluxcal::fit::internal {

// The observations of `in` that are data (screen.cc says what is not); what
// was left out is appended to `excluded` with its reason, the cells around
// a non-positive inductance to `not_pd`, and `row_index` holds the input
// index of each steady-state row kept.
FitData Screen(const FitData& in, std::vector<std::string>* excluded, std::vector<Calibration::Box>* not_pd,
               std::vector<size_t>* row_index);

// The rows' agreement: median of a per-row score and its robust spread
// (1.4826 MAD, Hampel), at least 1 (the scores are in sigmas). A row is
// judged by how far its score lies from the others', not from zero.
struct Consensus {
  double mid = 0, spread = 1;
};
Consensus RowConsensus(const std::vector<double>& z);

// How many robust spreads beyond the rows' agreement make a steady-state
// row an outlier: its torque against its voltages' (Screen), its flux
// against the fit of all other data (Fit, leaving one row out).
inline constexpr double kRowTorqueOutlier = 20.0;

// Rows a bench could not hold (the recording's extension columns,
// docs/recording-format.md): a row is excluded when the modulator was at
// its voltage limit, or the current controller clamped, for more than
// kRowLimitedShareMax of its averaging window, or when its current ripple
// relative to its current (RowRelativeRipple) exceeds kRowRippleMax; a
// row whose ripple widens its flux sigma (RowSigmaWb) by kRowRippleListed
// or more is listed as down-weighted. screen.cc says why these values.
inline constexpr double kRowLimitedShareMax = 0.05;
inline constexpr double kRowRippleMax = 1.0 / 3.0;
inline constexpr double kRowRippleListed = 1.1;

// A steady-state row's flux (from its voltages) against the fit's, in
// units of its sigma: the larger component.
double RowMisfit(const Calibration& cal, const FitData& d, const SteadyStateObservation& s);

}  // namespace fluxcal::fit::internal

#endif  // FLUXCAL_FITTING_SCREEN_H_
