// The catalogue's current_sensor_gain on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// Plausible within 0.8-1.25 (20 % either way): a phase current sensor
// further off fails any bench's plausibility check before it reaches a
// calibration, and a fit that puts every gain at 0.4 (a dead time on a
// deeply saturating machine at a quarter of the twin's current, the
// surfaces' misfit bent into a common gain) is a stand-in.
CatalogueEffect CurrentSensorGainEffect() {
  CatalogueEffect c;
  c.row = {"current_sensor_gain", "phase current sensors with unequal gains (measured = gain x true)",
           "a spurious HF component fixed in the stationary frame (not following 2 theta_e) and held currents off "
           "by a sensor gain: the phase current sensors have unequal gains (their mean is separated from Rs by the "
           "nominal Rs)",
           {{"gain_a", "1", 1.0, 1e-2, 0.0025, FloorKind::kAbsolute, 0.8, FloorScale::kNone, 1.25},
            {"gain_b", "1", 1.0, 1e-2, 0.0025, FloorKind::kAbsolute, 0.8, FloorScale::kNone, 1.25},
            {"gain_c", "1", 1.0, 1e-2, 0.0025, FloorKind::kAbsolute, 0.8, FloorScale::kNone, 1.25}}};
  c.keys = {{"gain_a", &Effects::gain_a, nullptr, nullptr, 0.0, true},
            {"gain_b", &Effects::gain_b, nullptr, nullptr, 0.0, true},
            {"gain_c", &Effects::gain_c, nullptr, nullptr, 0.0, true}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> {
    return {{"gain_a", e.gain_a}, {"gain_b", e.gain_b}, {"gain_c", e.gain_c}};
  };
  c.sense = [](const Effects& e, double* ia, double* ib, double* ic) {
    *ia = e.gain_a * *ia;
    *ib = e.gain_b * *ib;
    *ic = e.gain_c * *ic;
  };
  return c;
}

}  // namespace fluxcal::sim
