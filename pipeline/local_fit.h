// The fit of data held here (`fluxcal fit`), step by step as the command
// states them: the model name checked before any work, the fit input of
// each local source (a recording set, a bare hf_results.csv, a flux map),
// the machine facts merged (pipeline/facts.h), the fit, its figure. The
// stored fit (FitSerial) is pipeline/pipeline.h's; both read a set through
// FitDataFromSet (pipeline/points.h). fit::FitData and fit::Calibration are
// what these take and return, so this header exposes them.
#ifndef FLUXCAL_PIPELINE_LOCAL_FIT_H_
#define FLUXCAL_PIPELINE_LOCAL_FIT_H_

#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "fitting/fit.h"
#include "io/flux_map.h"
#include "io/recording_set.h"
#include "pipeline/facts.h"

namespace fluxcal::pipeline {

// OK for a model name the fit accepts (fit::ParseModelName); else
// InvalidArgument naming --model and every accepted name.
absl::Status CheckModelName(const std::string& name);

// The facts `set`'s manifest states merged with `stated` (ApplyStatedFacts
// for a recording set), checked before the (slow) identification: a
// conflict or a missing fact costs nothing, and identified points do not
// change them.
absl::Status CheckSetFacts(const io::RecordingSet& set, const StatedFacts& stated);

// A bare hf_results.csv's rows as fit input (no manifest: no facts).
fit::FitData FitDataFromHfResults(const std::vector<io::HfResultRow>& rows);

// A flux map's nodes as fit input (fit::FitDataFromFluxMap): each node's
// standard deviation psi_std_wb per component (<= 0: 0.2 % of the largest
// |psi|), psi_pm's prior from the node at (0, 0), the serial given.
fit::FitData FitDataFromFluxMap(const io::FluxMap& map, int pole_pairs, double psi_std_wb, const std::string& serial);

// The calibration of `data` with the model named (fit::Fit).
absl::StatusOr<fit::Calibration> FitCalibration(const fit::FitData& data, const std::string& model);

// The fit against the identified inductances it was fitted to (SVG).
std::string FitPlotSvg(const fit::Calibration& cal, const fit::FitData& data);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_LOCAL_FIT_H_
