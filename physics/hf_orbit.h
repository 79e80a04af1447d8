// The HF excursion as a large signal: what a rotating-voltage injection
// measures on a saturating machine (issue 27, item 1; docs/fitting.md,
// "Large-signal HF").
//
// Neglecting the resistive drop, the injected voltage V e^{j w_i t}
// (stationary frame) moves the flux linkage, in the rotor's dq frame, on a
// circle of radius rho = |V| / w_i about its mean: with psi_dq = C e^{j W t}
// and d psi_dq/dt = v_dq - j w_e psi_dq, v_dq = V e^{j (w_i - w_e) t}, one
// gets W = w_i - w_e and C = V / (j w_i), at any speed. The current follows
// the machine's own inverse flux map along that circle: an orbit i(theta)
// with mean i0 (what the identification reports as the point's current).
// The identification fits phasors at the injection frequency, i.e. it
// measures the first Fourier coefficients of flux and current along the
// orbit and solves them for a 2x2 inductance (identification/inductance.cc):
// the describing function of psi over the orbit (Gelb & Vander Velde,
// Multiple-Input Describing Functions, 1968, ch. 1), not the Jacobian at
// i0. For a one-axis characteristic psi = L x + c x^2/2 + d x^3/6 (x = i -
// i0) and flux amplitude b = L a, inverting the series (x = y/L - c y^2 /
// (2 L^3) + (c^2 / (2 L^5) - d / (6 L^4)) y^3), centring the circle so that
// the mean of x is 0 (its centre moves by c b^2 / (4 L^2)) and taking the
// first harmonic of x gives
//   L_eff = L + d a^2 / 8 - c^2 a^2 / (8 L) + O(a^4),
// so the knee's slope change (d) and the slope's own change (c) both move
// the measured value (6-9 % at a bridge knee with the twin's 5 V / 500 Hz
// on a 0.1 mH axis; tests/physics checks the formula).
//
// Two steps, both here because both belong to that one idea:
//   HfOrbit: the orbit's currents at n equally spaced phases theta_k =
//     2 pi k / n, from a flux map (Newton on psi(i) = psi_c + rho e^{j
//     theta_k}, psi_c adjusted so that the orbit's mean current is i0).
//   DescribingWeights: the weights W_k (3 x 2 each) with
//     (Ldd, Lqq, Ldq)_measured = sum_k W_k psi(i_k),
//     linear in the flux values at the orbit's currents, so a fit whose
//     surfaces are linear in their coefficients stays linear.
// The measured 2x2 inductance A solves Psi1 = A I1 (Psi1, I1 the first
// Fourier coefficients, complex 2-vectors: four real equations for A's four
// entries, A = [Re Psi1, Im Psi1] [Re I1, Im I1]^-1); the identification's
// four unknowns (S, D, R) take A's antisymmetric part as a resistance (it
// acts as j a on the phasor: j w (j a) I = -w a I), its symmetric part as
// the inductance: Ldd = A_dd, Lqq = A_qq, Ldq = (A_dq + A_qd) / 2.
// Header-only, double (the orbit is computed once per observation).
#ifndef FLUXCAL_PHYSICS_HF_ORBIT_H_
#define FLUXCAL_PHYSICS_HF_ORBIT_H_

#include <array>
#include <cmath>
#include <numbers>
#include <vector>

namespace fluxcal::physics {

// Phases per orbit: the describing function's error falls with the
// harmonics the sampling folds onto the first, ~(a / knee)^(n-1).
inline constexpr int kHfOrbitPhases = 16;

// The flux-circle radius of an injection of amplitude |V| at w_i, Wb.
inline double HfFluxRadiusWb(double voltage_v, double w_i_rad_s) { return std::abs(voltage_v / w_i_rad_s); }

// The orbit's currents (id_k, iq_k), k = 0..n-1, of a flux circle of radius
// rho_wb whose mean current is (id0, iq0). `map(id, iq, psi[2], L[3])`
// gives the flux and (Ldd, Lqq, Ldq) there. False (orbit left empty) where
// the map cannot be inverted along the circle (a singular or indefinite
// Jacobian, Newton not converging): the caller then keeps the small-signal
// value.
template <typename Map>
bool HfOrbit(const Map& map, double id0_a, double iq0_a, double rho_wb, std::vector<std::array<double, 2>>* orbit,
             int n = kHfOrbitPhases) {
  orbit->clear();
  if (!(rho_wb > 0) || n < 4) return false;
  double psi0[2], l0[3];
  map(id0_a, iq0_a, psi0, l0);
  const double det0 = l0[0] * l0[1] - l0[2] * l0[2];
  if (!(l0[0] > 0) || !(det0 > 0)) return false;
  // Newton on psi(i) = target from i; the step is halved while it does not
  // reduce |psi(i) - target| (a knee flattens the map and an undamped step
  // overshoots into the next branch).
  auto invert = [&](double td, double tq, double* id, double* iq) {
    double psi[2], l[3];
    map(*id, *iq, psi, l);
    double rd = psi[0] - td, rq = psi[1] - tq;
    const double tol = 1e-10 * (std::hypot(td, tq) + rho_wb);
    for (int it = 0; it < 50; ++it) {
      const double r = std::hypot(rd, rq);
      if (r <= tol) return true;
      const double det = l[0] * l[1] - l[2] * l[2];
      if (!(det > 0) || !(l[0] > 0)) return false;
      const double dd = (l[1] * rd - l[2] * rq) / det, dq = (l[0] * rq - l[2] * rd) / det;
      double step = 1.0;
      bool reduced = false;
      for (int h = 0; h < 20; ++h, step *= 0.5) {
        const double nd = *id - step * dd, nq = *iq - step * dq;
        double p2[2], l2[3];
        map(nd, nq, p2, l2);
        const double r2d = p2[0] - td, r2q = p2[1] - tq;
        if (std::hypot(r2d, r2q) < r) {
          *id = nd; *iq = nq; rd = r2d; rq = r2q;
          for (int c = 0; c < 3; ++c) l[c] = l2[c];
          reduced = true;
          break;
        }
      }
      if (!reduced) return std::hypot(rd, rq) <= 1e3 * tol;
    }
    return std::hypot(rd, rq) <= 1e3 * tol;
  };
  std::vector<std::array<double, 2>> pts(n);
  double cd = psi0[0], cq = psi0[1];
  for (int k = 0; k < n; ++k) {
    const double th = 2 * std::numbers::pi * k / n;
    const double ed = rho_wb * std::cos(th), eq = rho_wb * std::sin(th);
    pts[k] = {id0_a + (l0[1] * ed - l0[2] * eq) / det0, iq0_a + (l0[0] * eq - l0[2] * ed) / det0};
  }
  // The circle's centre: mean current i0 (the orbit's mean drifts from the
  // centre's current by the map's curvature; a fixed point with the
  // Jacobian at i0, converging in a few steps for orbits inside the map).
  for (int outer = 0; outer < 8; ++outer) {
    double md = 0, mq = 0;
    for (int k = 0; k < n; ++k) {
      const double th = 2 * std::numbers::pi * k / n;
      if (!invert(cd + rho_wb * std::cos(th), cq + rho_wb * std::sin(th), &pts[k][0], &pts[k][1])) return false;
      md += pts[k][0] / n;
      mq += pts[k][1] / n;
    }
    const double ed = md - id0_a, eq = mq - iq0_a;
    if (std::hypot(ed, eq) <= 1e-9 * (std::hypot(id0_a, iq0_a) + 1.0)) break;
    cd -= l0[0] * ed + l0[2] * eq;
    cq -= l0[2] * ed + l0[1] * eq;
  }
  *orbit = std::move(pts);
  return true;
}

// Weights of the describing function over `orbit` (HfOrbit's phases):
// w[c][k][j] with (Ldd, Lqq, Ldq)[c] = sum_k w[c][k][0] psi_d(i_k) +
// w[c][k][1] psi_q(i_k). False when the orbit's first harmonic is
// degenerate (a flat orbit: no 2x2 inverse).
inline bool DescribingWeights(const std::vector<std::array<double, 2>>& orbit,
                              std::array<std::vector<std::array<double, 2>>, 3>* w) {
  const int n = static_cast<int>(orbit.size());
  if (n < 4) return false;
  // I1 = (2/n) sum i_k e^{-j theta_k} per axis: M = [Re I1, Im I1] (2x2,
  // rows d, q).
  double m[2][2] = {{0, 0}, {0, 0}};
  for (int k = 0; k < n; ++k) {
    const double th = 2 * std::numbers::pi * k / n, c = std::cos(th), s = -std::sin(th);
    for (int a = 0; a < 2; ++a) {
      m[a][0] += 2.0 / n * orbit[k][a] * c;
      m[a][1] += 2.0 / n * orbit[k][a] * s;
    }
  }
  const double det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
  const double scale = std::abs(m[0][0] * m[1][1]) + std::abs(m[0][1] * m[1][0]);
  if (!(std::abs(det) > 1e-12 * scale) || !(scale > 0)) return false;
  // M^-1.
  const double inv[2][2] = {{m[1][1] / det, -m[0][1] / det}, {-m[1][0] / det, m[0][0] / det}};
  // A = P M^-1 with P = [Re Psi1, Im Psi1], P[a][0] = (2/n) sum psi_a,k cos,
  // P[a][1] = (2/n) sum psi_a,k (-sin): A[a][b] = sum_k psi_a,k g_b,k with
  // g_b,k = (2/n)(cos_k inv[0][b] - sin_k inv[1][b]).
  for (auto& c : *w) c.assign(n, {0.0, 0.0});
  for (int k = 0; k < n; ++k) {
    const double th = 2 * std::numbers::pi * k / n, c = std::cos(th), s = -std::sin(th);
    const double g0 = 2.0 / n * (c * inv[0][0] + s * inv[1][0]);
    const double g1 = 2.0 / n * (c * inv[0][1] + s * inv[1][1]);
    (*w)[0][k] = {g0, 0.0};               // A_dd = sum psi_d g0
    (*w)[1][k] = {0.0, g1};               // A_qq = sum psi_q g1
    (*w)[2][k] = {0.5 * g1, 0.5 * g0};    // (A_dq + A_qd)/2
  }
  return true;
}

}  // namespace fluxcal::physics

#endif  // FLUXCAL_PHYSICS_HF_ORBIT_H_
