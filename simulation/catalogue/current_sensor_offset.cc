// The catalogue's current_sensor_offset on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// An extension (docs/diagnosis-report.md, "Documented extensions"). A
// current sensor's DC offset: 0.1 % of a 250 A sensor's range is what an
// EOL offset calibration is held to; below it no table changes.
CatalogueEffect CurrentSensorOffsetEffect() {
  CatalogueEffect c;
  c.row = {"current_sensor_offset", "phase current sensors with a DC offset (measured = true + offset)",
           "held currents at standstill are off by a current fixed in the stationary frame (it does not follow the "
           "rotor angle) and torque at speed disagrees with the commanded current: the phase current sensors have "
           "DC offsets",
           {{"offset_a_a", "A", 0.0, 0.1, 0.25},
            {"offset_b_a", "A", 0.0, 0.1, 0.25},
            {"offset_c_a", "A", 0.0, 0.1, 0.25}},
           false};
  c.keys = {{"offset_a_a", &Effects::offset_a_a}, {"offset_b_a", &Effects::offset_b_a},
            {"offset_c_a", &Effects::offset_c_a}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> {
    return {{"offset_a_a", e.offset_a_a}, {"offset_b_a", e.offset_b_a}, {"offset_c_a", e.offset_c_a}};
  };
  c.sense = [](const Effects& e, double* ia, double* ib, double* ic) {
    *ia += e.offset_a_a;
    *ib += e.offset_b_a;
    *ic += e.offset_c_a;
  };
  return c;
}

}  // namespace fluxcal::sim
