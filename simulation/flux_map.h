// Gridded flux map: psi_d, psi_q tabulated on an (id, iq) grid (as FEA tools
// export them), interpolated reciprocally. The interpolant is a biquintic
// Hermite patch of the co-energy W'(id, iq) per cell, built from nodal W' and
// its derivatives up to second order in each variable (psi_d = W'_id,
// psi_q = W'_iq from the map; the higher ones by central differences of the
// map, mixed ones averaged over both orders). Flux is the patch's gradient,
// so d psi_d/d iq = d psi_q/d id holds exactly (mixed partials of one
// polynomial), and the co-energy is C2: flux linkage and differential
// inductance are continuous across cells (a C1 patch would make the
// inductance jump at the nodes, where operating points often sit). Nodal W'
// comes from integrating the map along id at iq = 0, then along iq (path
// independence of a conservative map).
#ifndef FLUXCAL_SIMULATION_FLUX_MAP_H_
#define FLUXCAL_SIMULATION_FLUX_MAP_H_

#include <vector>

#include "absl/status/statusor.h"
#include "simulation/magnetic_model.h"

namespace fluxcal::sim {

class GriddedFluxMap : public MagneticModel {
 public:
  // id_a, iq_a: strictly increasing axes (>= 4 nodes each); psi_*: row-major
  // [i_id * iq_a.size() + i_iq]. iq_a must start at 0 or be symmetric about
  // it; the map is mirrored to negative iq by the machine's symmetry.
  static absl::StatusOr<GriddedFluxMap> FromFluxGrid(std::vector<double> id_a, std::vector<double> iq_a,
                                                     const std::vector<double>& psi_d_wb,
                                                     const std::vector<double>& psi_q_wb,
                                                     double psi_pm_temp_coeff_per_k = -0.0012);
  // Samples another model on a grid (e.g. to make a map-family test motor).
  static GriddedFluxMap FromModel(const MagneticModel& m, double id_min, double id_max, int n_id,
                                  double iq_max, int n_iq);

  FluxLinkage Flux(double id_a, double iq_a, double temperature_c = 25.0) const override;
  DifferentialInductance Inductance(double id_a, double iq_a, double temperature_c = 25.0) const override;

 private:
  // W' and its derivatives at (id, iq >= 0) by the cell's Hermite patch.
  // Outside the grid: the co-energy's Taylor polynomial at the edge (flux_map.cc).
  void Eval(double id, double iq, double* wx, double* wy, double* wxx, double* wyy, double* wxy) const;
  // w[a][b] = d^(a+b) W' / did^a diq^b, a, b <= 2, by the cell's patch.
  void Derivatives(double id, double iq, double w[3][3]) const;
  std::vector<double> x_, y_;              // axes
  // Nodal co-energy derivatives D[p][q] = d^(p+q) W' / did^p diq^q, p, q <= 2.
  std::vector<double> d_[3][3];
  double psi_pm_wb_ = 0, temp_coeff_ = -0.0012;
};

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_FLUX_MAP_H_
