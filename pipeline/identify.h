// Identification of a recording set held here (`fluxcal identify SET`): the
// method named on the command line, and one result per operating point.
// The result and option types are identification/identify.h's
// (ident::HfPointResult, ident::IdentifyOptions): they are what this use
// case takes and returns, so this header exposes them. Identification as
// the fit and the store use it (identified points only): pipeline/points.h.
#ifndef FLUXCAL_PIPELINE_IDENTIFY_H_
#define FLUXCAL_PIPELINE_IDENTIFY_H_

#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "identification/identify.h"
#include "io/recording_set.h"

namespace fluxcal::pipeline {

// "paper" or "lsq"; InvalidArgument naming the ones there are.
absl::StatusOr<ident::Method> ParseIdentifyMethod(const std::string& name);
const char* IdentifyMethodName(ident::Method method);

// The flux radius of a point's rotating injection, Wb (docs/fitting.md,
// "Large-signal HF"; unset without a rotating injection in the manifest):
// what IdentifySet (points.h) puts on each point, `fluxcal identify --json`
// reports and the EOL client sends.
std::optional<double> InjectionFluxRadiusWb(const io::Manifest& manifest, const ident::HfPointResult& result);

// Every point of `set`, identified (failed points included, flagged).
absl::StatusOr<std::vector<ident::HfPointResult>> IdentifyEveryPoint(const io::RecordingSet& set,
                                                                     const ident::IdentifyOptions& options);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_IDENTIFY_H_
