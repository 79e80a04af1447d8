// The catalogue's differential_inductance on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// A modelling error of the tool that produced a calibration, not of a
// bench: the twin has no switch for it and diagnosis no block (the
// report's vocabulary keeps the name).
CatalogueEffect DifferentialInductanceEffect() {
  CatalogueEffect c;
  c.row = {"differential_inductance",
           "differential (HF) inductance used where apparent inductance / flux linkage is needed, or the reverse",
           "the mismatch between HF-identified and steady-state inductance grows with current: the differential "
           "inductance was taken as the apparent one",
           {}};
  c.truth = [](const Effects&) -> std::map<std::string, double> { return {}; };
  return c;
}

}  // namespace fluxcal::sim
