// The catalogue's dc_link_sense_gain on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// An extension. A DC-link voltage measurement off by a gain: the modulator
// divides the command by the measured voltage, so every applied voltage is
// scaled by 1/gain while currents and torque are untouched. 1 %: the
// tolerance of a production voltage divider; below it the voltage tables
// move less than psi_pm's own 1 % tolerance.
CatalogueEffect DcLinkSenseGainEffect() {
  CatalogueEffect c;
  c.row = {"dc_link_sense_gain", "DC-link voltage measurement off by a gain (measured = gain x true)",
           "every applied voltage (held DC, HF injection, back-EMF) is the command scaled by one common factor while "
           "the torque agrees with the currents: the DC-link voltage is measured with a gain error, so the "
           "modulator applies command / gain",
           {{"udc_sense_gain", "1", 1.0, 1e-2, 0.01}},
           false};
  c.keys = {{"udc_sense_gain", &Effects::udc_sense_gain, nullptr, nullptr, 0.0, true}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> { return {{"udc_sense_gain", e.udc_sense_gain}}; };
  // The modulator divides the command by the measured Udc.
  c.plant = [](const Effects& e, PlantModel* m) { m->voltage_gain = 1.0 / e.udc_sense_gain; };
  return c;
}

}  // namespace fluxcal::sim
