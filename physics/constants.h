// Mathematical constants of the physics kernel (physics/README in
// docs/architecture.md: one formula, one home).
#ifndef FLUXCAL_PHYSICS_CONSTANTS_H_
#define FLUXCAL_PHYSICS_CONSTANTS_H_

#include <numbers>

namespace fluxcal::physics {

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kSqrt3 = 1.7320508075688772935;

}  // namespace fluxcal::physics

#endif  // FLUXCAL_PHYSICS_CONSTANTS_H_
