// The catalogue's current_sensor_offset on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// An extension (docs/diagnosis-report.md, "Documented extensions"). A
// current sensor's DC offset: 0.1 % of a sensor's range is what an EOL
// offset calibration is held to, below which no table changes; with a
// sensor sized about 1.8x the largest test current (the twin's 250 A on
// its +-100 A plan) that is 0.18 % of the set's largest current (0.25 A
// there, 0.05 A on a 26 A machine).
CatalogueEffect CurrentSensorOffsetEffect() {
  CatalogueEffect c;
  c.row = {"current_sensor_offset", "phase current sensors with a DC offset (measured = true + offset)",
           "held currents at standstill are off by a current fixed in the stationary frame (it does not follow the "
           "rotor angle) and torque at speed disagrees with the commanded current: the phase current sensors have "
           "DC offsets",
           {{"offset_a_a", "A", 0.0, 0.1, 0.0018, FloorKind::kAbsolute, -1e300, FloorScale::kCurrentMax},
            {"offset_b_a", "A", 0.0, 0.1, 0.0018, FloorKind::kAbsolute, -1e300, FloorScale::kCurrentMax},
            {"offset_c_a", "A", 0.0, 0.1, 0.0018, FloorKind::kAbsolute, -1e300, FloorScale::kCurrentMax}},
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
