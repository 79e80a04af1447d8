// The interface every flux-linkage model in fluxcal implements: the twin's
// true motors (analytic, gridded map), the fitted calibrations, and what the
// table generators and diagnosis evaluate. SI units; dq frame per
// docs/recording-format.md.
//
// Differential (incremental) inductance is the Jacobian of flux linkage:
//   Ldd = d psi_d/d id, Lqq = d psi_q/d iq, Ldq = d psi_d/d iq (= d psi_q/d id
//   for a conservative model, i.e. psi = grad W'(i) of a co-energy W').
#ifndef FLUXCAL_SIMULATION_MAGNETIC_MODEL_H_
#define FLUXCAL_SIMULATION_MAGNETIC_MODEL_H_

namespace fluxcal::sim {

struct FluxLinkage {
  double psi_d_wb = 0.0;
  double psi_q_wb = 0.0;
};

struct DifferentialInductance {
  double ldd_h = 0.0;
  double lqq_h = 0.0;
  double ldq_h = 0.0;   // symmetric: d psi_d/d iq = d psi_q/d id
};

class MagneticModel {
 public:
  virtual ~MagneticModel() = default;
  // Flux linkage at the given currents and magnet temperature.
  virtual FluxLinkage Flux(double id_a, double iq_a,
                           double temperature_c = 25.0) const = 0;
  // Jacobian of Flux() with respect to (id, iq).
  virtual DifferentialInductance Inductance(double id_a, double iq_a,
                                            double temperature_c = 25.0) const = 0;
  // Both at one point: what Newton steps on the surfaces need. A model
  // whose two share work (a spline's basis) overrides it; the values are
  // those of Flux() and Inductance().
  virtual void FluxAndInductance(double id_a, double iq_a, double temperature_c, FluxLinkage* flux,
                                 DifferentialInductance* inductance) const {
    *flux = Flux(id_a, iq_a, temperature_c);
    *inductance = Inductance(id_a, iq_a, temperature_c);
  }
};

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_MAGNETIC_MODEL_H_
