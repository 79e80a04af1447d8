// The twin's plant (internal to simulation/): the ODE right-hand side in
// the true rotor frame with flux linkages as states, the inverter's dead-time
// error, and an RK4 step with a held voltage. Shared by the bench
// (bench.cc) and the replays (replay.cc); unit-tested against analytic
// solutions in tests/simulation/plant_test.cc. Equations: docs/simulation.md.
#ifndef FLUXCAL_SIMULATION_PLANT_H_
#define FLUXCAL_SIMULATION_PLANT_H_

#include <algorithm>
#include <cmath>

#include "simulation/bench_effect.h"
#include "simulation/frames.h"
#include "simulation/magnetic_model.h"
#include "simulation/saturation_model.h"

namespace fluxcal::sim {

struct Vec2 {
  double d = 0, q = 0;
};

// Everything the ODE right-hand side needs for one operating point.
struct PlantModel {
  double p[kSaturationParams];   // saturation parameters with psi_pm(T)
  const MagneticModel* map = nullptr;   // replaces p when set
  double map_temperature_c = 25.0, map_psi_shift_wb = 0.0;
  double rs_ohm;
  double r_hf_ohm;
  double hf_corner_rad_s = 2 * kPi * 50.0;   // eddy branch: high-pass corner
  int order = 0;
  double amplitude_h = 0;
  double dead_time_s = 0, dead_time_i_th_a = 1, udc_v = 50, ts_s = 1e-4;
  double u_max_v = 50 / kSqrt3;
  // dc_link_sense_gain: the modulator divides the command by the measured
  // Udc, so the applied voltage is command x voltage_gain (= 1 / gain).
  double voltage_gain = 1.0;
  // phase_resistance_imbalance: extra resistance per phase (a bad joint).
  double dr_a_ohm = 0, dr_b_ohm = 0, dr_c_ohm = 0;
  // inverter_voltage_drop: the conducting switch's threshold V_th sign(i_x)
  // (in DeadTimeError: the same soft sign as the dead time) and its slope
  // r_on i_x (in Derivative: a series resistance in every phase).
  double threshold_v = 0, slope_ohm = 0;
  // iron_loss: conductance 1 / R_fe of a resistance in parallel with the
  // magnetising branch (0: none). The flux follows the magnetising current
  // i_m; the terminals carry i_m + g e, e the voltage across the branch.
  double g_fe_s = 0;
  // Physics outside the catalogue (simulation/bench_effect.h), and what its
  // mechanical angle needs: th_m = (th_e + 2 pi sector) / pole_pairs.
  const BenchEffects* unmodelled = nullptr;
  int pole_pairs = 4, sector = 0;

  double MechanicalAngle(double th) const { return physics::MechanicalAngle(th, sector, pole_pairs); }
  double PsiPm() const { return map ? map->Flux(0, 0, map_temperature_c).psi_d_wb + map_psi_shift_wb : p[0]; }
  void Unmodelled(double th, double* pd, double* pq, double* ldd, double* lqq, double* ldq) const {
    if (unmodelled == nullptr || unmodelled->empty()) return;
    const double psi_pm = PsiPm();
    for (const auto& e : *unmodelled) e->ModifyMagnetics(th, MechanicalAngle(th), psi_pm, pd, pq, ldd, lqq, ldq);
  }

  // psi(i, theta) including the spatial-harmonic term amp cos(n theta) i and
  // the physics outside the catalogue.
  void Flux(double id, double iq, double th, double* pd, double* pq) const {
    BaseFlux(id, iq, th, pd, pq);
    Unmodelled(th, pd, pq, nullptr, nullptr, nullptr);
  }
  void Jacobian(double id, double iq, double th, double* ldd, double* lqq, double* ldq) const {
    BaseJacobian(id, iq, th, ldd, lqq, ldq);
    if (unmodelled != nullptr && !unmodelled->empty()) {
      // ModifyMagnetics takes the flux beside the inductance.
      double pd, pq;
      BaseFlux(id, iq, th, &pd, &pq);
      Unmodelled(th, &pd, &pq, ldd, lqq, ldq);
    }
  }
  void BaseFlux(double id, double iq, double th, double* pd, double* pq) const {
    if (map) {
      const auto f = map->Flux(id, iq, map_temperature_c);
      *pd = f.psi_d_wb + map_psi_shift_wb;
      *pq = f.psi_q_wb;
    } else {
      SaturationFlux(id, iq, p, pd, pq);
    }
    if (order != 0) {
      const double h = amplitude_h * std::cos(order * th);
      *pd += h * id;
      *pq += h * iq;
    }
  }
  void BaseJacobian(double id, double iq, double th, double* ldd, double* lqq, double* ldq) const {
    if (map) {
      const auto l = map->Inductance(id, iq, map_temperature_c);
      *ldd = l.ldd_h;
      *lqq = l.lqq_h;
      *ldq = l.ldq_h;
    } else {
      SaturationInductance(id, iq, p, ldd, lqq, ldq);
    }
    if (order != 0) {
      const double h = amplitude_h * std::cos(order * th);
      *ldd += h;
      *lqq += h;
    }
  }
  // i(psi) by Newton from a warm start; converges in 2-3 steps because the
  // model is smooth and the start is the previous sub-step's current.
  // Damped (backtracking on |psi - psi(i)|^2, Nocedal & Wright, Numerical
  // Optimization, 2nd ed., alg. 3.1): the Newton step J^-1 r is a descent
  // direction of that norm wherever J is invertible, so halving it until
  // the residual falls always ends. Where the HF current ellipse sweeps
  // through a knee (a bridge-knee machine at 60 A: Lqq falls 10x within a
  // few amperes) the full step from the previous current overshot past the
  // measured region, into a fitted surface's continuation with Ldd < 0, and
  // the replay ran away (1e40 A within 50 ms). A full step that reduces the
  // residual, and every tiny one, is taken as before: the iterates of a
  // converging solve are unchanged bit for bit.
  Vec2 Current(double psd, double psq, double th, Vec2 guess) const {
    Vec2 i = guess;
    double pd, pq;
    Flux(i.d, i.q, th, &pd, &pq);
    for (int it = 0; it < 20; ++it) {
      double a, b, c;
      Jacobian(i.d, i.q, th, &a, &b, &c);
      const double rd = psd - pd, rq = psq - pq;
      const double det = a * b - c * c;
      const double dd = (b * rd - c * rq) / det, dq = (a * rq - c * rd) / det;
      if (!std::isfinite(dd) || !std::isfinite(dq)) break;
      const double size = std::abs(dd) + std::abs(dq), scale = 1.0 + std::abs(i.d) + std::abs(i.q);
      if (size < 1e-12 * scale) {
        i.d += dd;
        i.q += dq;
        break;
      }
      const double r2 = rd * rd + rq * rq;
      double t = 1.0;
      Vec2 next = i;
      for (int halvings = 0; halvings < 40; ++halvings, t *= 0.5) {
        next = Vec2{i.d + t * dd, i.q + t * dq};
        Flux(next.d, next.q, th, &pd, &pq);
        const double n2 = (psd - pd) * (psd - pd) + (psq - pq) * (psq - pq);
        if (n2 < r2 || t * size < 1e-9 * scale) break;
      }
      i = next;
    }
    return i;
  }
};

// Inverter voltage error of an uncompensated dead time and of the switches'
// threshold voltage, per phase -((Td/Ts) Udc + V_th) tanh(i_x / i_th),
// common mode removed, in alpha-beta (amplitude-invariant Clarke). The
// paper's eq. (9) is its Fourier series. The dead time's part scales with
// Udc, the threshold's does not: what separates them (docs/simulation.md).
void DeadTimeError(const PlantModel& m, double ia, double ib, double ic, double* ua, double* ub);

struct State {
  double psd, psq;       // flux linkage in the true dq frame
  double lpd, lpq;       // low-passed current (eddy branch)
  Vec2 i;                // magnetising current consistent with psi (cache)
  Vec2 i_term{};         // terminal current: i plus the iron-loss current (= i without iron loss)
};

// dx/dt in the true rotor frame: dpsi/dt = e - w J psi with e, the voltage
// across the magnetising branch, = (u - Rs i_m - R_hf (i_m - i_lp)) / (1 + Rs g)
// (u = Rs (i_m + g e) + e solved for e; g = 0 without iron loss). i_out: the
// magnetising current; i_terminal (optional): i_m + g e. Dead time, the
// switches' and the joints' drops see the phase currents of i_m: the loss
// current is a percent of it.
void Derivative(const PlantModel& m, const State& x, double th, double we, double ual, double ube,
                double* dpsd, double* dpsq, double* dlpd, double* dlpq, Vec2* i_out, Vec2* i_terminal = nullptr);

// One RK4 step of length h with a held alpha-beta voltage.
void Rk4(const PlantModel& m, State* x, double th0, double we, double h, double ual, double ube);

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_PLANT_H_
