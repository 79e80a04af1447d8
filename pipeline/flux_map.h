// A calibration against flux maps, the two local use cases: written as a
// flux map psi(id, iq) or its inverse i(psi) (`fluxcal map export`), and
// compared with a measured map in a current region (`fluxcal compare`). The
// grid, region and comparison types are tables/flux_map_export.h's: this
// use case takes and returns them, so this header exposes them.
#ifndef FLUXCAL_PIPELINE_FLUX_MAP_H_
#define FLUXCAL_PIPELINE_FLUX_MAP_H_

#include <cstddef>
#include <string>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "io/flux_map.h"
#include "tables/flux_map_export.h"

namespace fluxcal::pipeline {

// The grid a map export takes when none is given: the calibration's
// measured region, 21 x 21 nodes (forward), or the fluxes of that region
// (inverse).
void DefaultFluxMapGrid(const fit::Calibration& cal, bool inverse, tables::LinearAxis* a, tables::LinearAxis* b);

struct FluxMapExport {
  std::string csv;            // the file's text
  size_t rows = 0;            // nodes
  int valid_nodes = 0;        // inverse: nodes whose currents were found
  int extrapolated = 0;       // forward: nodes outside the measured region
  bool zero_current_node = true;   // forward: the grid has a node at id = iq = 0 (readers detect the axes from it)
};
// The forward map psi(id, iq) on the current grid (a, b), or with `inverse`
// the inverse map i(psi) on the flux grid (a, b). Errors: InvalidArgument
// for a grid out of range (forward: field 'grid id' / 'grid iq'), the
// inversion's and the CSV writer's.
absl::StatusOr<FluxMapExport> ExportFluxMap(const fit::Calibration& cal, const tables::LinearAxis& a,
                                            const tables::LinearAxis& b, bool inverse);

// The box the calibration was fitted on (no margin, iq >= 0 side).
tables::CurrentRegion MeasuredCurrentRegion(const fit::Calibration& cal);
// The calibration's flux error over the map's nodes inside `region`.
absl::StatusOr<tables::FluxMapComparison> CompareWithFluxMap(const fit::Calibration& cal, const io::FluxMap& map,
                                                             const tables::CurrentRegion& region);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_FLUX_MAP_H_
