// The catalogue's hf_resistance on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// Material from 18 % of the nominal Rs (2 mOhm on the twin's 11 mOhm
// winding), about the 15 % a resistance is held to (dead_time.cc).
CatalogueEffect HfResistanceEffect() {
  CatalogueEffect c;
  c.row = {"hf_resistance", "extra series resistance at the injection frequency (eddy currents, iron loss)",
           "the positive-sequence HF current leads the injected voltage by more than the winding resistance "
           "explains: extra series resistance at the injection frequency (eddy currents)",
           {{"r_hf_ohm", "ohm", 0.0, 1e-3, 0.18, FloorKind::kAbsolute, 0.0, FloorScale::kRsNominal}}};
  c.keys = {{"r_hf_ohm", &Effects::r_hf_ohm, nullptr, nullptr, 0.0}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> { return {{"r_hf_ohm", e.r_hf_ohm}}; };
  c.plant = [](const Effects& e, PlantModel* m) { m->r_hf_ohm = e.r_hf_ohm; };
  return c;
}

}  // namespace fluxcal::sim
