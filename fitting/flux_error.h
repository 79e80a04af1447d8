// The flux error of a model against known flux linkages (a map's nodes), in
// one place: Fit reports it over a map fit's nodes (FitSummary::flux_*),
// `fluxcal compare` over a map's nodes in a region
// (tables::CompareWithFluxMap), both through FluxErrorOverNodes.
//
// Per node e = |psi_model - psi_node| = hypot(ed, eq) with ed, eq the d and
// q errors (model - node); RMS sqrt(mean e^2) and max e, in Wb and relative
// to the largest |psi| = hypot(psi_d, psi_q) among the nodes (the figure of
// merit docs/fitting.md states for maps).
#ifndef FLUXCAL_FITTING_FLUX_ERROR_H_
#define FLUXCAL_FITTING_FLUX_ERROR_H_

#include <cstddef>
#include <vector>

#include "io/flux_map.h"
#include "simulation/magnetic_model.h"

namespace fluxcal::fit {

struct FluxNodeError {
  int nodes = 0;
  double psi_scale_wb = 0;                     // largest |psi| among the nodes
  double rms_wb = 0, max_wb = 0;
  // rms_wb, max_wb / psi_scale_wb; with no scale (every node at zero flux)
  // 0 if the error is 0 too, else infinity.
  double rms_relative = 0, max_relative = 0;
  double rms_d_wb = 0, rms_q_wb = 0;           // per axis
  size_t worst = 0;                            // index of the node with the largest e
  double worst_error_d_wb = 0, worst_error_q_wb = 0;   // model - node there
};

// Over every node given (none: all zero).
FluxNodeError FluxErrorOverNodes(const sim::MagneticModel& model, const std::vector<io::FluxMapPoint>& nodes);

}  // namespace fluxcal::fit

#endif  // FLUXCAL_FITTING_FLUX_ERROR_H_
