// Flux maps out of a calibration, and a calibration held against a map
// (docs/fitting.md, "Flux maps in and out"):
//   - the forward map psi(id, iq) sampled on a current grid (io::FluxMap,
//     written by io::WriteFluxMapCsv);
//   - the inverse map i(psi_d, psi_q) on a regular flux grid, which
//     flux-based current controllers and observers look up;
//   - the flux error of a model against a map's nodes in a current region.
// Conventions as in io/flux_map.h: dq frame on the magnet axis,
// amplitude-invariant Clarke (peak-valued currents in A), flux in Wb.
#ifndef FLUXCAL_TABLES_FLUX_MAP_EXPORT_H_
#define FLUXCAL_TABLES_FLUX_MAP_EXPORT_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "io/flux_map.h"
#include "simulation/magnetic_model.h"

namespace fluxcal::tables {

// n equally spaced values from min to max inclusive (n = 1: just min).
struct LinearAxis {
  double min = 0, max = 0;
  int n = 1;
  std::vector<double> Values() const;
};
inline constexpr int kMaxFluxMapAxisNodes = 1000;

// Closed box of currents; iq bounds signed (no mirroring).
struct CurrentRegion {
  double id_min_a = 0, id_max_a = 0, iq_min_a = 0, iq_max_a = 0;
  bool Contains(double id_a, double iq_a) const {
    return id_a >= id_min_a && id_a <= id_max_a && iq_a >= iq_min_a && iq_a <= iq_max_a;
  }
};

// The box a calibration was fitted on, as stored (no margin, iq >= 0 side):
// id in [id_min_a, id_max_a], iq in [iq_min_a, iq_max_a].
CurrentRegion MeasuredRegion(const fit::Calibration& cal);

// Default current grid: the measured region, 21 x 21 nodes.
void DefaultCurrentGrid(const fit::Calibration& cal, LinearAxis* id, LinearAxis* iq);

// Any model sampled on the grid. InvalidArgument (field 'grid id' or
// 'grid iq') unless each axis has 1..kMaxFluxMapAxisNodes finite nodes,
// max > min when n > 1.
absl::StatusOr<io::FluxMap> SampleFluxMap(const sim::MagneticModel& model, const LinearAxis& id,
                                          const LinearAxis& iq);

struct CalibrationFluxMap {
  io::FluxMap map;
  int extrapolated = 0;   // nodes outside Calibration::InMeasuredRegion
};
absl::StatusOr<CalibrationFluxMap> SampleCalibration(const fit::Calibration& cal, const LinearAxis& id,
                                                     const LinearAxis& iq);

// ---- Inverse map i(psi) --------------------------------------------------

struct InverseFluxMapOptions {
  // A node is valid when |Flux(i) - psi| <= tolerance_wb (Euclidean) at a
  // solution i inside the measured box itself, id in [id_min_a, id_max_a],
  // |iq| in [iq_min_a, iq_max_a] (without the 2 % margin of
  // Calibration::InMeasuredRegion): a controller's table must not lean on
  // extrapolated magnetics.
  double tolerance_wb = 1e-10;
  int max_iterations = 60;
};

struct InverseFluxMap {
  std::vector<double> psi_d_wb, psi_q_wb;            // axes
  // [i][j] at (psi_d_wb[i], psi_q_wb[j]); NaN where not valid.
  std::vector<std::vector<double>> id_a, iq_a;
  std::vector<std::vector<uint8_t>> valid;
  int valid_nodes = 0;
  size_t size() const { return psi_d_wb.size() * psi_q_wb.size(); }
};

// Default flux grid: the bounding box of the calibration's flux over its
// measured region (iq >= 0 side), 21 x 21 nodes. Corners of that box lie
// outside the curved image of the region and come out invalid.
void DefaultFluxGrid(const fit::Calibration& cal, LinearAxis* psi_d, LinearAxis* psi_q);

// Solves Flux(id, iq) = (psi_d, psi_q) at every node by damped, projected
// Newton iteration (flux_map_export.cc explains the method). InvalidArgument
// (field 'psi grid ...') for a bad axis as SampleFluxMap; nodes with no
// solution in the measured box are marked invalid, never an error.
absl::StatusOr<InverseFluxMap> InvertCalibration(const fit::Calibration& cal, const LinearAxis& psi_d,
                                                 const LinearAxis& psi_q, const InverseFluxMapOptions& options = {});

// CSV: header `psi_d_Vs,psi_q_Vs,id_A,iq_A,valid`, psi_d slowest, numbers
// with 17 significant digits; an invalid node has empty id_A, iq_A cells and
// valid 0.
std::string InverseFluxMapCsv(const InverseFluxMap& inv);

// ---- Model against a map ---------------------------------------------------

struct FluxMapComparison {
  CurrentRegion region;
  int nodes = 0;                       // map nodes inside the region
  double psi_scale_wb = 0;             // largest |psi| = hypot(psi_d, psi_q) among them
  // e = |psi_model - psi_map| (Euclidean over d and q) per node:
  double rms_wb = 0, max_wb = 0;       // sqrt(mean e^2), max e
  double rms_relative = 0, max_relative = 0;   // the same / psi_scale_wb
  double rms_d_wb = 0, rms_q_wb = 0;   // per axis
  io::FluxMapPoint worst;              // the map's node with the largest e
  double worst_error_d_wb = 0, worst_error_q_wb = 0;   // model - map there
};

// The map's nodes inside the region through fit::FluxErrorOverNodes (the
// one home of the error, fitting/flux_error.h). InvalidArgument naming the
// map's source and field 'region' when no node lies inside the region.
absl::StatusOr<FluxMapComparison> CompareWithFluxMap(const sim::MagneticModel& model, const io::FluxMap& map,
                                                     const CurrentRegion& region);

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TABLES_FLUX_MAP_EXPORT_H_
