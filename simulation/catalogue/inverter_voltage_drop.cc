// The catalogue's inverter_voltage_drop on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// An extension. The switches' on-state voltage: a threshold V_th sign(i_x)
// (IGBT collector-emitter knee, diode forward voltage) plus a slope
// r_on i_x, per phase, opposing the current. With one DC-link voltage the
// threshold has exactly the dead time's current-sign pattern
// (Td = V_th Ts / Udc); the dead-time error scales with Udc and the
// threshold does not, so a plan that repeats locked points at a second Udc
// separates them. The slope is in series with Rs in every response seen
// through the inverter's commands (docs/diagnosis.md): diagnosis names it
// as an alternative of stator_resistance, never alone. Threshold 0.1 % of
// Udc: the dead time's own floor (0.1 us) at 10 kHz (0.05 V at 50 V);
// slope 9 % of the nominal Rs, as phase_resistance_imbalance.
CatalogueEffect InverterVoltageDropEffect() {
  CatalogueEffect c;
  c.row = {"inverter_voltage_drop",
           "inverter on-state voltage drop: threshold V_th sign(i_x) plus slope r_on i_x per phase",
           "the voltage that holds each standstill current departs from Rs i by a current-sign pattern that does not "
           "scale with the DC-link voltage (the points repeated at a second Udc show the same step): the inverter's "
           "switches drop a threshold voltage (IGBT knee / diode forward voltage), not a dead time",
           {{"threshold_v", "V", 0.0, 0.1, 0.001, FloorKind::kAbsolute, 0.0, FloorScale::kUdc},
            {"slope_ohm", "ohm", 0.0, 1e-3, 0.09, FloorKind::kAbsolute, 0.0, FloorScale::kRsNominal}},
           false};
  c.keys = {{"threshold_v", &Effects::threshold_v}, {"slope_ohm", &Effects::slope_ohm}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> {
    return {{"threshold_v", e.threshold_v}, {"slope_ohm", e.slope_ohm}};
  };
  c.plant = [](const Effects& e, PlantModel* m) {
    m->threshold_v = e.threshold_v;
    m->slope_ohm = e.slope_ohm;
  };
  return c;
}

}  // namespace fluxcal::sim
