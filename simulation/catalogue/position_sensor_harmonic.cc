// The catalogue's position_sensor_harmonic on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

#include <cmath>
#include <limits>

#include "simulation/frames.h"

namespace fluxcal::sim {

// An extension. A production defect of the angle sensor an EOL station
// calibrates out: a resolver with unequal sine/cosine winding amplitudes
// (or an encoder disc mounted off-centre on a sensor with the motor's pole
// count) reads true + a sin(2 theta_e + phase). position_offset is its
// constant part only. 0.25 electrical degrees, as position_offset: the
// torque error it leaves is then below the tables' tolerance. The phase
// alone is never material (infinite floor): the amplitude is.
CatalogueEffect PositionSensorHarmonicEffect() {
  CatalogueEffect c;
  c.row = {"position_sensor_harmonic",
           "angle sensor error at twice the electrical angle (resolver amplitude imbalance, eccentric encoder disc): "
           "measured = true + amplitude sin(2 theta_e + phase)",
           "the saliency's phase (negative-sequence current) at standstill swings with the rotor angle as "
           "sin(2 theta_e), not by one constant angle: the angle sensor reads true + amplitude sin(2 theta_e + phase) "
           "(a resolver's unequal winding amplitudes or an eccentric encoder disc)",
           {{"harmonic_amplitude_rad", "rad", 0.0, 1e-2, 0.25 * kPi / 180, FloorKind::kAbsolute, 0.0},
            {"harmonic_phase_rad", "rad", 0.0, 1.0, std::numeric_limits<double>::infinity()}},
           false};
  c.keys = {{"harmonic_amplitude_rad", &Effects::harmonic_amplitude_rad},
            {"harmonic_phase_rad", &Effects::harmonic_phase_rad}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> {
    return {{"harmonic_amplitude_rad", e.harmonic_amplitude_rad}, {"harmonic_phase_rad", e.harmonic_phase_rad}};
  };
  c.angle_error = [](const Effects& e, double theta_true_rad) {
    return e.harmonic_amplitude_rad * std::sin(2 * theta_true_rad + e.harmonic_phase_rad);
  };
  c.active = [](const Effects& e) { return e.harmonic_amplitude_rad != 0; };
  return c;
}

}  // namespace fluxcal::sim
