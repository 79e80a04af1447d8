// The catalogue's magnet_temperature on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// The magnets' true flux (the manifest keeps the nominal one), or a rise of
// their temperature over the test (psi_pm follows the motor's temperature
// coefficient).
CatalogueEffect MagnetTemperatureEffect() {
  CatalogueEffect c;
  c.row = {"magnet_temperature", "magnet flux linkage differs from nominal / drifts with temperature",
           "back-EMF in the steady-state voltages and torque differ from the nominal magnet flux (magnet "
           "temperature or magnetisation)",
           {{"psi_pm_wb", "Wb", 0.0, 1e-2, 0.005, FloorKind::kRelativeNominal},
            // A drift (documented extension): psi_pm at the first and last
            // steady-state row in recording order.
            {"psi_pm_start_wb", "Wb", 0.0, 1e-2, 0.005, FloorKind::kRelativeNominal},
            {"psi_pm_end_wb", "Wb", 0.0, 1e-2, 0.005, FloorKind::kRelativeNominal}}};
  c.keys = {{"psi_pm_wb", nullptr, &Effects::psi_pm_wb, nullptr, 0.0},
            {"magnet_temp_rise_k", &Effects::magnet_temp_rise_k}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> {
    return {{"psi_pm_wb", e.psi_pm_wb.value_or(0.0)}};
  };
  c.active = [](const Effects& e) { return e.psi_pm_wb.has_value() || e.magnet_temp_rise_k != 0.0; };
  return c;
}

}  // namespace fluxcal::sim
