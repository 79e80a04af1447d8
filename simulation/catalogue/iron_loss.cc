// The catalogue's iron_loss on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

// An extension. Iron loss (eddy currents and hysteresis in the laminations)
// as a resistance in parallel with the magnetising branch: the loss current
// g e makes no flux and no torque. At the injection frequency it is an HF
// resistance matrix w^2 g L^2 (unlike hf_resistance: larger on the axis of
// larger inductance, falling with saturation); at speed the back-EMF drives
// g w J psi, which the measured current includes and the torque does not.
// Fitted as the conductance g = 1 / R_fe (0 = none, the neutral); material
// below 600 X, X = w_i (Ld + Lq) / 2 the machine's HF reactance (its loss
// current then 1/600 of the HF current and more): on the twin (X = 0.82
// Ohm) about 500 ohm, where w_i^2 g L^2 reaches hf_resistance's 2 mOhm.
CatalogueEffect IronLossEffect() {
  CatalogueEffect c;
  c.row = {"iron_loss",
           "iron loss as a resistance in parallel with the magnetising branch (R_fe): loss current without flux or "
           "torque",
           "the HF resistance is larger on the axis of larger inductance and falls with saturation (w^2 L^2 / R_fe), "
           "and at speed the measured current exceeds what the torque needs by the back-EMF over a resistance: iron "
           "loss in a resistance R_fe parallel to the magnetising inductance",
           // fit_scale: of the conductance, in S.
           {{"r_fe_ohm", "ohm", 0.0, 0.01, 600.0, FloorKind::kBelow, 0.0, FloorScale::kReactance}},
           false};
  c.keys = {{"r_fe_ohm", &Effects::r_fe_ohm, nullptr, nullptr, 0.0}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> { return {{"r_fe_ohm", e.r_fe_ohm}}; };
  c.plant = [](const Effects& e, PlantModel* m) { m->g_fe_s = e.r_fe_ohm > 0 ? 1.0 / e.r_fe_ohm : 0.0; };
  return c;
}

}  // namespace fluxcal::sim
