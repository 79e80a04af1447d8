// The catalogue's sampling_delay on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

CatalogueEffect SamplingDelayEffect() {
  CatalogueEffect c;
  c.row = {"sampling_delay", "extra delay between voltage command and its application",
           "HF current lags the command by a phase proportional to frequency and the steady-state voltages are "
           "rotated by w_e times the same time: extra delay between command and inverter",
           {{"delay_s", "s", 0.0, 1e-6, 2e-6, FloorKind::kAbsolute, 0.0}}};
  c.keys = {{"delay_s", &Effects::delay_s, nullptr, nullptr, 0.0}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> { return {{"delay_s", e.delay_s}}; };
  return c;
}

}  // namespace fluxcal::sim
