// Reference-frame and timing helpers of the twin and diagnosis: the
// formulas live in the physics kernel (physics/frames.h, physics/speed.h,
// physics/delay.h); this header names them in fluxcal::sim for the double
// callers.
#ifndef FLUXCAL_SIMULATION_FRAMES_H_
#define FLUXCAL_SIMULATION_FRAMES_H_

#include <complex>

#include "physics/constants.h"
#include "physics/delay.h"
#include "physics/frames.h"
#include "physics/speed.h"

namespace fluxcal::sim {

using physics::kPi;
using physics::kSqrt3;
using physics::kCopperAlphaPerK;

using AlphaBeta = physics::AlphaBeta<double>;
using Phases = physics::Phases<double>;

using physics::Clarke;
using physics::InverseClarke;
using physics::InversePark;
using physics::InverseParkCs;
using physics::Park;
using physics::ParkCs;
using physics::WrapAngle;
using physics::ZohGain;
inline std::complex<double> ClarkeComplex(double a, double b, double c) {
  const AlphaBeta ab = Clarke(a, b, c);
  return {ab.alpha, ab.beta};
}
// Electrical angular speed [rad/s] from mechanical speed [rpm] and back.
inline double RpmToElectricalRadS(double speed_rpm, int pole_pairs) {
  return physics::RpmToElectricalRadS(speed_rpm, pole_pairs);
}
inline double ElectricalRadSToRpm(double w_e_rad_s, int pole_pairs) {
  return physics::ElectricalRadSToRpm(w_e_rad_s, pole_pairs);
}
inline double Sinc(double x) { return physics::Sinc(x); }

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_FRAMES_H_
