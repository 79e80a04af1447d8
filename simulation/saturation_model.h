// Analytic, conservative saturation model of an IPMSM, templated on the
// scalar so that the simulator (double) and the Ceres fits (ceres::Jet)
// evaluate the same equations.
//
// Co-energy (docs/simulation.md, eq. (M1)):
//   W'(id, iq) = psi_pm id + Ld0 Id^2 (sqrt(1 + (id/Id)^2) - 1)
//              + Lq0 Iq^2 (sqrt(1 + (iq/Iq)^2) - 1) - (g/2) iq^2 (1 + id/Ix)
// Flux linkage is its gradient (so the differential inductance, the Hessian,
// is symmetric by construction):
//   psi_d = psi_pm + Ld0 id / sqrt(1 + (id/Id)^2) - (g/2) iq^2 / Ix
//   psi_q = Lq0 iq / sqrt(1 + (iq/Iq)^2) - g iq (1 + id/Ix)
// psi_q(id, 0) = 0 and psi_d(0, 0) = psi_pm as the machine's symmetry needs.
// g = 0 switches cross saturation off (Ldq = -g iq / Ix).
// Self-axis saturation: Ldd = Ld0 (1 + (id/Id)^2)^{-3/2}, likewise Lqq.
#ifndef FLUXCAL_SIMULATION_SATURATION_MODEL_H_
#define FLUXCAL_SIMULATION_SATURATION_MODEL_H_

#include <cmath>

namespace fluxcal::sim {

// Parameter vector shared with fitting/: kSaturationParams doubles in this
// order.
struct SaturationParams {
  double psi_pm_wb = 0.0114;   // magnet flux linkage at 25 degC
  double ld0_h = 0.181e-3;     // unsaturated d-axis inductance
  double lq0_h = 0.372e-3;     // unsaturated q-axis inductance
  double id_sat_a = 420.0;     // d-axis saturation current
  double iq_sat_a = 280.0;     // q-axis saturation current
  double g_cross_h = 0.0;      // cross-saturation strength
  double ix_a = 100.0;         // cross-saturation current scale
};
inline constexpr int kSaturationParams = 7;

inline void ToArray(const SaturationParams& p, double* a) {
  a[0] = p.psi_pm_wb; a[1] = p.ld0_h; a[2] = p.lq0_h; a[3] = p.id_sat_a;
  a[4] = p.iq_sat_a; a[5] = p.g_cross_h; a[6] = p.ix_a;
}
inline SaturationParams FromArray(const double* a) {
  return SaturationParams{a[0], a[1], a[2], a[3], a[4], a[5], a[6]};
}

// psi(i) from eq. (M1). T: double or ceres::Jet. p: kSaturationParams values.
template <typename T, typename P>
void SaturationFlux(const T& id, const T& iq, const P* p, T* psi_d, T* psi_q) {
  using std::sqrt;
  const T xd = id / p[3], xq = iq / p[4];
  *psi_d = p[0] + p[1] * id / sqrt(T(1.0) + xd * xd) - T(0.5) * p[5] * iq * iq / p[6];
  *psi_q = p[2] * iq / sqrt(T(1.0) + xq * xq) - p[5] * iq * (T(1.0) + id / p[6]);
}

// Hessian of W' (the differential inductance), analytic.
template <typename T, typename P>
void SaturationInductance(const T& id, const T& iq, const P* p, T* ldd, T* lqq, T* ldq) {
  using std::sqrt;
  const T xd = id / p[3], xq = iq / p[4];
  const T sd = T(1.0) + xd * xd, sq = T(1.0) + xq * xq;
  *ldd = p[1] / (sd * sqrt(sd));
  *lqq = p[2] / (sq * sqrt(sq)) - p[5] * (T(1.0) + id / p[6]);
  *ldq = -p[5] * iq / p[6];
}

// Both at one point (the tables' Newton steps need both): the values of
// SaturationFlux and SaturationInductance to the last bit (the same
// operations in the same order), with the quotients and square roots they
// share evaluated once.
inline void SaturationFluxAndInductance(double id, double iq, const double* p, double* psi_d, double* psi_q,
                                        double* ldd, double* lqq, double* ldq) {
  const double xd = id / p[3], xq = iq / p[4];
  const double sd = 1.0 + xd * xd, sq = 1.0 + xq * xq;
  const double rd = std::sqrt(sd), rq = std::sqrt(sq);
  const double cross = 1.0 + id / p[6];
  *psi_d = p[0] + p[1] * id / rd - 0.5 * p[5] * iq * iq / p[6];
  *psi_q = p[2] * iq / rq - p[5] * iq * cross;
  *ldd = p[1] / (sd * rd);
  *lqq = p[2] / (sq * rq) - p[5] * cross;
  *ldq = -p[5] * iq / p[6];
}

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_SATURATION_MODEL_H_
