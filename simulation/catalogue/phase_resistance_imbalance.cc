// The catalogue's phase_resistance_imbalance on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// An extension. A bad joint (crimp, weld, terminal) adds resistance to one
// phase. Its common part is stator_resistance; the rest is reported as a
// zero-sum set. 9 % of the nominal Rs (1 mOhm on the twin's 11 mOhm
// winding): about the resistance spread a production line accepts between
// phases.
CatalogueEffect PhaseResistanceImbalanceEffect() {
  CatalogueEffect c;
  c.row = {"phase_resistance_imbalance", "unequal phase resistances, e.g. a bad joint (extra ohm per phase)",
           "the DC voltage that holds a standstill current depends on the current's direction in the stationary "
           "frame (twice the angle), with no matching HF component in the stationary frame and no change at speed: "
           "the phase resistances differ (a bad joint)",
           {{"dr_a_ohm", "ohm", 0.0, 1e-3, 0.09, FloorKind::kAbsolute, -1e300, FloorScale::kRsNominal},
            {"dr_b_ohm", "ohm", 0.0, 1e-3, 0.09, FloorKind::kAbsolute, -1e300, FloorScale::kRsNominal},
            {"dr_c_ohm", "ohm", 0.0, 1e-3, 0.09, FloorKind::kAbsolute, -1e300, FloorScale::kRsNominal}},
           false};
  c.keys = {{"dr_a_ohm", &Effects::dr_a_ohm}, {"dr_b_ohm", &Effects::dr_b_ohm}, {"dr_c_ohm", &Effects::dr_c_ohm}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> {
    return {{"dr_a_ohm", e.dr_a_ohm}, {"dr_b_ohm", e.dr_b_ohm}, {"dr_c_ohm", e.dr_c_ohm}};
  };
  c.plant = [](const Effects& e, PlantModel* m) {
    m->dr_a_ohm = e.dr_a_ohm;
    m->dr_b_ohm = e.dr_b_ohm;
    m->dr_c_ohm = e.dr_c_ohm;
  };
  return c;
}

}  // namespace fluxcal::sim
