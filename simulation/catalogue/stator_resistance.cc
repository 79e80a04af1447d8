// The catalogue's stator_resistance on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// The winding's true resistance; the manifest keeps the nominal one.
CatalogueEffect StatorResistanceEffect() {
  CatalogueEffect c;
  c.row = {"stator_resistance", "winding resistance differs from nominal",
           "the DC voltage that holds each standstill current scales with a resistance other than the nominal one",
           {{"rs_ohm", "ohm", 0.0, 1e-3, 0.03, FloorKind::kRelativeNominal, 0.0}}};
  c.keys = {{"rs_ohm", nullptr, &Effects::rs_ohm, nullptr, 0.0, true}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> { return {{"rs_ohm", e.rs_ohm.value_or(0.0)}}; };
  c.active = [](const Effects& e) { return e.rs_ohm.has_value(); };
  return c;
}

}  // namespace fluxcal::sim
