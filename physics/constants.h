// Constants of the physics kernel (docs/architecture.md, "The physics
// kernel: one formula, one home").
#ifndef FLUXCAL_PHYSICS_CONSTANTS_H_
#define FLUXCAL_PHYSICS_CONSTANTS_H_

#include <numbers>

namespace fluxcal::physics {

inline constexpr double kPi = std::numbers::pi;
inline constexpr double kSqrt3 = 1.7320508075688772935;
// Temperature coefficient of annealed copper's resistance at 20 degC [1/K]
// (IEC 60028: 0.00393): R(T) = R(T0) (1 + alpha (T - T0)) near room
// temperature.
inline constexpr double kCopperAlphaPerK = 0.00393;

}  // namespace fluxcal::physics

#endif  // FLUXCAL_PHYSICS_CONSTANTS_H_
