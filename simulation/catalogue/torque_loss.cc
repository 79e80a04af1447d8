// The catalogue's torque_loss on the twin's side (simulation/catalogue/catalogue_effect.h).
#include "simulation/catalogue/catalogue_effect.h"

#include "physics/torque.h"
#include "simulation/frames.h"

namespace fluxcal::sim {

// An extension. Every torque transducer sits behind bearings and seals: it
// reads the air-gap torque less friction (opposing the rotation) and drag
// (growing with speed), and has a zero of its own (one direction of
// rotation cannot tell it from the friction). Fitted on the steady-state
// rows' torque only (the voltages pin the magnet flux and the currents).
// 0.33 % of the largest torque the rows record (0.05 N m on the twin's 15 N
// m): about the torque rows' own uncertainty (0.02 N m + 0.5 %) over a few
// rows, below which no torque table changes; drag as that at 1000 rpm.
CatalogueEffect TorqueLossEffect() {
  CatalogueEffect c;
  c.row = {"torque_loss",
           "mechanical loss between the air gap and the torque transducer: friction T_f sign(n) (with the "
           "transducer's zero) plus drag b w_m",
           "the measured torque falls short of the air-gap torque that the voltages and currents give by an amount "
           "that does not scale with the current and grows with the speed, while the voltages agree with the magnet "
           "flux: friction and drag between the air gap and the torque transducer (bearings, seals, windage), or the "
           "transducer's zero",
           {{"friction_nm", "N m", 0.0, 0.1, 0.0033, FloorKind::kAbsolute, -1e300, FloorScale::kTorqueMax},
            {"viscous_nm_per_rad_s", "N m s", 0.0, 1e-3, 0.0033 / (1000 * 2 * kPi / 60), FloorKind::kAbsolute, 0.0,
             FloorScale::kTorqueMax}},
           false};
  c.keys = {{"friction_nm", &Effects::friction_nm}, {"viscous_nm_per_rad_s", &Effects::viscous_nm_per_rad_s}};
  c.truth = [](const Effects& e) -> std::map<std::string, double> {
    return {{"friction_nm", e.friction_nm}, {"viscous_nm_per_rad_s", e.viscous_nm_per_rad_s}};
  };
  // physics/torque.h: sign(n) (T_f + b |w_m|); the truth file keeps the
  // air-gap torque.
  c.torque_loss = [](const Effects& e, double speed_rpm) {
    return physics::MechanicalLossTorque(e.friction_nm, e.viscous_nm_per_rad_s, speed_rpm);
  };
  return c;
}

}  // namespace fluxcal::sim
