// Reference frames (docs/recording-format.md, "Conventions"):
//  - amplitude-invariant Clarke: x_alpha = (2 a - b - c) / 3,
//    x_beta = (b - c) / sqrt(3); a balanced set of peak X maps to a vector of
//    length X, and the zero sequence (a + b + c) / 3 drops out;
//  - its inverse for a set without zero sequence: a = alpha,
//    b,c = -alpha / 2 +- sqrt(3) / 2 beta;
//  - Park: x_d + j x_q = (x_alpha + j x_beta) e^{-j theta_e}, theta_e the
//    electrical angle of the rotor d axis (magnet north) from phase a.
// Templated on the scalar so ceres::Jet differentiates through them.
#ifndef FLUXCAL_PHYSICS_FRAMES_H_
#define FLUXCAL_PHYSICS_FRAMES_H_

#include <cmath>

#include "physics/constants.h"

namespace fluxcal::physics {

template <typename T = double>
struct AlphaBeta {
  T alpha{0}, beta{0};
};
template <typename T = double>
struct Phases {
  T a{0}, b{0}, c{0};
};

// Amplitude-invariant Clarke transform (the zero sequence drops out).
template <typename T>
AlphaBeta<T> Clarke(const T& a, const T& b, const T& c) {
  return {(2.0 * a - b - c) / 3.0, (b - c) / kSqrt3};
}
// Inverse Clarke without zero sequence.
template <typename T>
Phases<T> InverseClarke(const T& alpha, const T& beta) {
  return {alpha, -0.5 * alpha + 0.5 * kSqrt3 * beta, -0.5 * alpha - 0.5 * kSqrt3 * beta};
}
// Park: stationary -> rotor frame at electrical angle theta (rotation by
// -theta), and its inverse (rotation by +theta). The *Cs forms take
// c = cos(theta), s = sin(theta) already at hand (inner loops that rotate
// several vectors by one angle).
template <typename T, typename A>
void ParkCs(const T& alpha, const T& beta, const A& c, const A& s, T* d, T* q) {
  *d = c * alpha + s * beta;
  *q = -s * alpha + c * beta;
}
template <typename T, typename A>
void InverseParkCs(const T& d, const T& q, const A& c, const A& s, T* alpha, T* beta) {
  *alpha = c * d - s * q;
  *beta = s * d + c * q;
}
template <typename T, typename A>
void Park(const T& alpha, const T& beta, const A& theta, T* d, T* q) {
  using std::cos;
  using std::sin;
  ParkCs(alpha, beta, A(cos(theta)), A(sin(theta)), d, q);
}
template <typename T, typename A>
void InversePark(const T& d, const T& q, const A& theta, T* alpha, T* beta) {
  using std::cos;
  using std::sin;
  InverseParkCs(d, q, A(cos(theta)), A(sin(theta)), alpha, beta);
}
// Angle wrapped to [0, 2 pi).
inline double WrapAngle(double a) {
  a = std::fmod(a, 2 * kPi);
  return a < 0 ? a + 2 * kPi : a;
}

}  // namespace fluxcal::physics

#endif  // FLUXCAL_PHYSICS_FRAMES_H_
