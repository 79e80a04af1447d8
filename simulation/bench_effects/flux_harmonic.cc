// A spatial harmonic of the magnet's flux linkage (slotting, magnet shape):
// in the rotor frame psi_d += h cos(n th_e + phase), psi_q += h sin(n th_e +
// phase), n = 6 by default: the 5th and 7th harmonics of the back-EMF in
// the stator. Independent of the current (the catalogue's
// spatial_harmonics is an inductance that varies with the angle); at
// standstill it is a constant flux and invisible, at speed it drives
// currents at harmonics of the electrical frequency.
#include <cmath>

#include "simulation/bench_effects/simple.h"

namespace fluxcal::sim {
namespace {

class FluxHarmonic : public SimpleBenchEffect {
 public:
  FluxHarmonic()
      : SimpleBenchEffect({{"psi_harmonic_wb", "Wb", 0.0, "amplitude of the magnet flux's spatial harmonic"},
                           {"psi_harmonic_order", "1", 6.0, "its order in the electrical angle (rotor frame)"},
                           {"psi_harmonic_phase_rad", "rad", 0.0, "its phase"}},
                          1) {}
  std::string_view Name() const override { return "magnet_flux_harmonic"; }
  std::string_view Meaning() const override {
    return "the magnet's flux linkage varies with the rotor angle (back-EMF harmonics)";
  }
  void ModifyMagnetics(double th_e, double /*th_m*/, double /*psi_pm_wb*/, double* psi_d, double* psi_q, double*,
                       double*, double*) const override {
    const double a = Value(1) * th_e + Value(2);
    *psi_d += Value(0) * std::cos(a);
    *psi_q += Value(0) * std::sin(a);
  }
};

}  // namespace

std::unique_ptr<BenchEffect> MakeFluxHarmonic() { return std::make_unique<FluxHarmonic>(); }

}  // namespace fluxcal::sim
