// The flags of every subcommand that reads a flux map (`fit --map`,
// `compare`): which convention the file is in (io/flux_map.h,
// FluxMapConvention), and how the one applied is shown.
//   --convention auto|fluxcal|motulator|syre   axes (default auto: detected
//                                              from the zero-current node)
//   --current peak|rms|power-invariant         current scaling (default peak)
//   --flux-amplitude peak|rms|power-invariant  flux scaling (default peak)
//   --units Wb|Vs|mWb|mVs                      flux unit (default: the
//                                              header's suffix, else Wb)
#ifndef FLUXCAL_CLI_SUPPORT_FLUX_MAP_H_
#define FLUXCAL_CLI_SUPPORT_FLUX_MAP_H_

#include "absl/status/statusor.h"
#include "cli/args.h"
#include "io/flux_map.h"
#include "nlohmann/json.hpp"

namespace fluxcal::cli {

// The four flags above, to append to a command's FlagSpecs.
FlagSpecs FluxMapConventionFlags();
// True if any of them is given.
bool HasFluxMapConventionFlag(const ParsedArgs& args);
// The convention they name; InvalidArgument "flag --units: expected Wb, Vs,
// mWb or mVs, got 'x'" for a value not listed.
absl::StatusOr<io::FluxMapConvention> FluxMapConventionFromArgs(const ParsedArgs& args);
// {"axes", "axes_source" (detected|flag), "current", "flux_amplitude",
//  "flux_unit", "flux_unit_source", "current_factor", "flux_factor",
//  "detail", "description"}
nlohmann::json FluxMapConventionJson(const io::AppliedFluxMapConvention& c);

}  // namespace fluxcal::cli

#endif  // FLUXCAL_CLI_SUPPORT_FLUX_MAP_H_
