// The catalogue's spatial_harmonics on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// The inductance's dependence on the rotor angle at cos(order theta_e);
// material from 0.38 % of the mean HF inductance (1 uH on the twin's 0.26
// mH), about the identification's accuracy.
CatalogueEffect SpatialHarmonicsEffect() {
  CatalogueEffect c;
  c.row = {"spatial_harmonics", "inductance varies with rotor angle beyond the 2 theta_e term",
           "the identified inductance at standstill varies with rotor angle as cos(order theta_e), beyond the "
           "saliency's 2 theta_e",
           {{"order", "1", 0.0, 1.0, 0.0}, {"amplitude_h", "H", 0.0, 1e-6, 0.0038, FloorKind::kAbsolute, -1e300, FloorScale::kInductance}}};
  c.keys = {{"order", nullptr, nullptr, &Effects::order}, {"amplitude_h", &Effects::amplitude_h}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> {
    return {{"order", e.order}, {"amplitude_h", e.amplitude_h}};
  };
  c.active = [](const Effects& e) { return e.order != 0 && e.amplitude_h != 0; };
  c.plant = [](const Effects& e, PlantModel* m) {
    m->order = e.order;
    m->amplitude_h = e.amplitude_h;
  };
  return c;
}

}  // namespace fluxcal::sim
