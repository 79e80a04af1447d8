// The catalogue's dead_time on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// Scales and floors (all rows): the scale puts each fitted parameter at
// order one (what Ceres' trust region sees); the floor is a fraction of the
// tolerance a calibration is held to (dead time 20 %, resistance 15 %,
// offset 0.5 electrical degrees, gains 0.5 %, psi_pm 1 %), below which no
// calibration decision changes however precisely the data pin the value
// down.
CatalogueEffect DeadTimeEffect() {
  CatalogueEffect c;
  c.row = {"dead_time",
           "uncompensated inverter dead time / device drop: voltage error following the sign of each phase current",
           "voltage error that follows the sign of each phase current: the held DC commands depart from Rs i by a "
           "current-sign pattern and the HF response is distorted where a phase current lingers near zero "
           "(uncompensated inverter dead time or device drop)",
           {{"dead_time_s", "s", 0.0, 1e-6, 0.1e-6}}};
  // The soft sign's current scale, tanh(i / i_th) (physics/inverter.h).
  c.keys = {{"dead_time_s", &Effects::dead_time_s},
            {"dead_time_i_th_a", &Effects::dead_time_i_th_a, nullptr, nullptr, 0.0, true}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> {
    return {{"dead_time_s", e.dead_time_s}, {"i_th_a", e.dead_time_i_th_a}};
  };
  c.plant = [](const Effects& e, PlantModel* m) {
    m->dead_time_s = e.dead_time_s;
    m->dead_time_i_th_a = e.dead_time_i_th_a;
  };
  return c;
}

}  // namespace fluxcal::sim
