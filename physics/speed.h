// Speed and angle conversions between the mechanical shaft and the
// electrical frame (docs/recording-format.md): speed columns are mechanical
// rpm, w_e = p n 2 pi / 60 (p pole pairs; one mechanical turn is p
// electrical turns), and the mechanical angle of a rotor standing in pole
// pair `sector` at electrical angle theta_e is (theta_e + 2 pi sector) / p.
#ifndef FLUXCAL_PHYSICS_SPEED_H_
#define FLUXCAL_PHYSICS_SPEED_H_

#include "physics/constants.h"

namespace fluxcal::physics {

// Electrical angular speed [rad/s] from mechanical speed [rpm].
template <typename T>
T RpmToElectricalRadS(const T& speed_rpm, int pole_pairs) {
  return speed_rpm * static_cast<double>(pole_pairs) * 2.0 * kPi / 60.0;
}
// Mechanical speed [rpm] from electrical angular speed [rad/s].
template <typename T>
T ElectricalRadSToRpm(const T& w_e_rad_s, int pole_pairs) {
  return w_e_rad_s * 60.0 / (2.0 * kPi * static_cast<double>(pole_pairs));
}
// Mechanical angular speed [rad/s] from mechanical speed [rpm]: w_m = 2 pi n / 60.
template <typename T>
T RpmToMechanicalRadS(const T& speed_rpm) {
  return speed_rpm * 2.0 * kPi / 60.0;
}
// Mechanical angle [rad] of electrical angle theta_e in pole pair `sector`.
template <typename T>
T MechanicalAngle(const T& theta_e_rad, int sector, int pole_pairs) {
  return (theta_e_rad + 2 * kPi * sector) / static_cast<double>(pole_pairs < 1 ? 1 : pole_pairs);
}

}  // namespace fluxcal::physics

#endif  // FLUXCAL_PHYSICS_SPEED_H_
