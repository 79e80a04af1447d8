// The catalogue's cross_saturation on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// The twin's magnetics with a cross term of strength g_cross [H]
// (simulation/saturation_model.h). No parameter of its own in the report:
// diagnosis takes a machine's cross saturation as part of its calibration
// (docs/diagnosis.md, "The baseline"), never as a finding.
CatalogueEffect CrossSaturationEffect() {
  CatalogueEffect c;
  c.row = {"cross_saturation", "psi_d depends on iq and psi_q on id; Ldq != 0",
           "the HF response needs Ldq != 0 and Ldd depending on iq: psi_d depends on iq and psi_q on id (cross "
           "saturation), modelled by cross terms of the co-energy",
           {}};
  c.keys = {{"cross_saturation", &Effects::cross_saturation}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> { return {{"strength_h", e.cross_saturation}}; };
  c.active = [](const Effects& e) { return e.cross_saturation != 0; };
  return c;
}

}  // namespace fluxcal::sim
