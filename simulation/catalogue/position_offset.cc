// The catalogue's position_offset on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

#include "simulation/frames.h"

namespace fluxcal::sim {

CatalogueEffect PositionOffsetEffect() {
  CatalogueEffect c;
  c.row = {"position_offset", "angle sensor offset: measured = true + offset",
           "the saliency (negative-sequence phase) and the steady-state voltages are rotated by a constant angle: "
           "the angle sensor reads true + offset",
           {{"offset_rad", "rad", 0.0, 1e-2, 0.25 * kPi / 180}}};
  c.keys = {{"offset_rad", &Effects::offset_rad}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> { return {{"offset_rad", e.offset_rad}}; };
  c.angle_error = [](const Effects& e, double) { return e.offset_rad; };
  return c;
}

}  // namespace fluxcal::sim
