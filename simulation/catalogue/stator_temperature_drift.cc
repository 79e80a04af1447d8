// The catalogue's stator_temperature_drift on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// An extension. The winding warms during the test (copper +0.393 %/K): Rs
// grows along the test's order. 5 K: 2 % of Rs, below stator_resistance's
// own 3 % floor.
CatalogueEffect StatorTemperatureDriftEffect() {
  CatalogueEffect c;
  c.row = {"stator_temperature_drift",
           "the winding warms during the test: Rs rises linearly over the locked points (copper +0.393 %/K)",
           "the resistance the held DC voltages need rises with the order the points were recorded in: the winding "
           "warmed during the test",
           {{"winding_temp_rise_k", "K", 0.0, 1.0, 5.0}},
           false};
  c.keys = {{"winding_temp_rise_k", &Effects::winding_temp_rise_k}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> {
    return {{"winding_temp_rise_k", e.winding_temp_rise_k}};
  };
  return c;
}

}  // namespace fluxcal::sim
