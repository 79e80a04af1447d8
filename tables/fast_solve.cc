// The fast solves of the field-weakening table (tables/internal_solver.h):
// Newton iterations in (id, iq) started next to the answer, each accepted
// only where its checks place it where the robust solve (solver.cc) lands.
#include <cmath>

#include "physics/torque.h"
#include "tables/internal_solver.h"
#include "tables/tables.h"

namespace fluxcal::tables {
namespace internal {

// The least-current point of torque t on the voltage limit |u| = u_max, by
// a 2-D Newton on F = (T(id, iq) - t, |u(id, iq)|^2 - u_max^2) from a nearby
// start (the row's cell at the previous speed, or its MTPA point). The
// robust solve (TrySolve) reaches the same point as the root along the
// constant-torque locus of g(id) = |u(id, iq(id))| - u_max by regula falsi,
// each step a locus solve (~10-20 of them, and ~60 more for the locus' MTPV
// point where its end at -i_max violates the voltage limit); here it is ~3-5
// surface evaluations and one locus solve for the check.
// The answer is accepted only where it is the point the robust solve finds:
//  - converged: T = t as tightly as a locus solve, |u|^2 = u_max^2 to 1e-10;
//  - on the branch of the locus that the robust solve follows: the locus
//    solve from its cold start at id* gives the same iq (beyond the measured
//    region the torque is not monotone in iq, and a start carried over from
//    another point can settle on another root; this catches it);
//  - inside the robust solve's bracket: -i_max <= id* <= `id_hi` (the MTPA
//    point's id when known);
//  - on the MTPA side of the locus' MTPV point: along the locus towards
//    larger id the voltage rises (dg/did > 0) and the current falls
//    (d|i|^2/did < 0). |u| and |i| each have one minimum along the locus
//    (the robust solve's own premise), so g has one root between the MTPV
//    and the MTPA point, and the voltage at the MTPA point exceeds u_max:
//    this root is the robust solve's.
// Otherwise false, and the caller solves robustly.
bool FwNewton(const sim::MagneticModel& m, const MachineLimits& lim, double t, double we, double s, double id0,
              double iq0, double id_hi, double* id_out, double* iq_out, sim::FluxLinkage* flux_out) {
  const double u_max = lim.UMaxV(), u2 = u_max * u_max;
  const double rs = *lim.rs_ohm;   // a voltage limit (we > 0 in field weakening) has Rs
  const double k = 1.5 * lim.pole_pairs;
  double id = id0, iq = iq0;
  for (int it = 0; it < 16; ++it) {
    sim::FluxLinkage F;
    sim::DifferentialInductance L;
    m.FluxAndInductance(id, iq, lim.temperature_c, &F, &L);
    const double f1 = physics::ElectromagneticTorque(lim.pole_pairs, F.psi_d_wb, F.psi_q_wb, id, iq) - t;
    const double ud = rs * id - we * F.psi_q_wb, uq = rs * iq + we * F.psi_d_wb;
    const double f2 = ud * ud + uq * uq - u2;
    // Jacobian, with d psi_d/d id = Ldd, d psi_d/d iq = d psi_q/d id = Ldq,
    // d psi_q/d iq = Lqq: T = 1.5 p (psi_d iq - psi_q id) and
    // u = (Rs id - we psi_q, Rs iq + we psi_d).
    const double t_d = k * (L.ldd_h * iq - F.psi_q_wb - L.ldq_h * id);
    const double t_q = physics::TorqueSlopeIq(lim.pole_pairs, F.psi_d_wb, L.ldq_h, L.lqq_h, id, iq);
    const double g_d = 2 * (ud * (rs - we * L.ldq_h) + uq * we * L.ldd_h);
    const double g_q = 2 * (-ud * we * L.lqq_h + uq * (rs + we * L.ldq_h));
    if (std::abs(f1) < 1e-10 * (1.0 + std::abs(t)) && std::abs(f2) <= 1e-10 * u2) {
      if (!(s * iq > -1e-9 && id >= -lim.i_max_a && id <= id_hi && t_q > 0)) return false;
      // Along the locus diq/did = -T_d / T_q.
      const double diq = -t_d / t_q;
      if (!(g_d + g_q * diq > 0) || !(id + iq * diq < 0)) return false;
      double iq_cold;
      sim::FluxLinkage f_cold;
      if (!SolveIqForTorque(m, lim, id, t, s, &iq_cold, 0.0, &f_cold) ||
          !(std::abs(iq_cold - iq) <= 1e-6 * (1.0 + std::abs(iq)))) {
        return false;
      }
      // iq as the robust solve gives it: from the locus solve at id.
      *id_out = id;
      *iq_out = iq_cold;
      if (flux_out != nullptr) *flux_out = f_cold;
      return true;
    }
    // A step longer than a quarter of the current limit is shortened.
    if (!DampedNewtonStep(t_d, t_q, g_d, g_q, f1, f2, 0.25 * lim.i_max_a, &id, &iq)) return false;
  }
  return false;
}

// The MTPA point of torque t (the least current on its locus), by a 2-D
// Newton on F = (T(id, iq) - t, id T_q - iq T_d) from a nearby start (the
// MTPA point of the neighbouring torque row). The second equation says the
// current's gradient (id, iq) is parallel to the torque's (T_d, T_q): the
// first-order condition of the least current on T = t. Its Jacobian needs
// the inductances' derivatives, which the models do not give: forward
// differences of (T_d, T_q) (two more evaluations per step; they only set
// the steps, the answer is F = 0). The robust solve (TrySolve) scans the
// locus at 17 points and refines the best by golden section: ~58 locus
// solves against ~12 evaluations and three locus solves to check here.
// Accepted only where it is the point the robust solve finds:
//  - converged: T = t as tightly as a locus solve, the condition to 1e-10
//    of |i| |grad T|;
//  - on the branch of the locus that the robust solve follows (the locus
//    solve from its cold start at id* gives the same iq, as FwNewton);
//  - inside the robust search's interval [-i_max, 0];
//  - a minimum: the current at the locus points 1e-4 i_max either side
//    (cold locus solves) exceeds the current at id*. |i| has one minimum
//    along the locus (the golden section's own premise), so this is the
//    one the robust solve converges to.
bool MtpaNewton(const sim::MagneticModel& m, const MachineLimits& lim, double t, double s, double id0, double iq0,
                double* id_out, double* iq_out) {
  const double k = 1.5 * lim.pole_pairs;
  // T_d, T_q at (id, iq): T = 1.5 p (psi_d iq - psi_q id).
  auto grad = [&](double id, double iq, double* t_d, double* t_q) {
    sim::FluxLinkage F;
    sim::DifferentialInductance L;
    m.FluxAndInductance(id, iq, lim.temperature_c, &F, &L);
    *t_d = k * (L.ldd_h * iq - F.psi_q_wb - L.ldq_h * id);
    *t_q = physics::TorqueSlopeIq(lim.pole_pairs, F.psi_d_wb, L.ldq_h, L.lqq_h, id, iq);
    return physics::ElectromagneticTorque(lim.pole_pairs, F.psi_d_wb, F.psi_q_wb, id, iq);
  };
  const double h = 1e-6 * lim.i_max_a;
  double id = id0, iq = iq0;
  for (int it = 0; it < 16; ++it) {
    double t_d, t_q;
    const double f1 = grad(id, iq, &t_d, &t_q) - t;
    const double f2 = id * t_q - iq * t_d;
    if (std::abs(f1) < 1e-10 * (1.0 + std::abs(t)) &&
        std::abs(f2) <= 1e-10 * std::hypot(id, iq) * std::hypot(t_d, t_q)) {
      if (!(s * iq > 0 && id >= -lim.i_max_a && id <= 0 && t_q > 0)) return false;
      double iq_cold, q_lo, q_hi;
      const double d = 1e-4 * lim.i_max_a;
      if (!SolveIqForTorque(m, lim, id, t, s, &iq_cold) ||
          !(std::abs(iq_cold - iq) <= 1e-6 * (1.0 + std::abs(iq))) ||
          !SolveIqForTorque(m, lim, id - d, t, s, &q_lo) || !SolveIqForTorque(m, lim, id + d, t, s, &q_hi)) {
        return false;
      }
      const double c0 = id * id + iq_cold * iq_cold;
      if (!((id - d) * (id - d) + q_lo * q_lo > c0 && (id + d) * (id + d) + q_hi * q_hi > c0)) return false;
      *id_out = id;
      *iq_out = iq_cold;
      return true;
    }
    // d f2 = T_q + id dT_q/did - iq dT_d/did (along id), id dT_q/diq - T_d -
    // iq dT_d/diq (along iq); dT/did = T_d, dT/diq = T_q for f1.
    double td_a, tq_a, td_b, tq_b;
    grad(id + h, iq, &td_a, &tq_a);
    grad(id, iq + h, &td_b, &tq_b);
    const double f2_d = t_q + id * (tq_a - t_q) / h - iq * (td_a - t_d) / h;
    const double f2_q = id * (tq_b - t_q) / h - t_d - iq * (td_b - t_d) / h;
    if (!DampedNewtonStep(t_d, t_q, f2_d, f2_q, f1, f2, 0.25 * lim.i_max_a, &id, &iq)) return false;
  }
  return false;
}

// The limit torque where it is the MTPV point of the voltage limit (above
// the speed from which the current limit no longer binds at the maximum):
// the point of |u| = u_max where the torque's gradient is parallel to the
// voltage's, by a 2-D Newton on F = (|u|^2 - u_max^2, T_d G_q - T_q G_d)
// (G = grad |u|^2) from the previous speed's, the second row of the
// Jacobian by forward differences (the inductances' derivatives are not
// given; they only set the steps). Accepted where it lies strictly inside
// the current limit, on the motoring/generating side asked for, and the
// torque grows outwards (s grad T = l grad |u|^2 with l > 0: a maximum, not
// a minimum, of the torque over the inside of the voltage limit nearby).
// Whether it is the largest, the caller's check decides (PassesLimitCheck:
// its search above the limit covers the whole locus).
bool MtpvLimit(const sim::MagneticModel& m, const MachineLimits& lim, double we, double s, double id0, double iq0,
               LimitTorque* out) {
  const double u_max = lim.UMaxV(), u2 = u_max * u_max;
  const double rs = *lim.rs_ohm;
  const double k = 1.5 * lim.pole_pairs;
  struct Local { double torque, t_d, t_q, c, g_d, g_q; };
  auto at = [&](double id, double iq) {
    sim::FluxLinkage F;
    sim::DifferentialInductance L;
    m.FluxAndInductance(id, iq, lim.temperature_c, &F, &L);
    const double ud = rs * id - we * F.psi_q_wb, uq = rs * iq + we * F.psi_d_wb;
    Local r;
    r.torque = physics::ElectromagneticTorque(lim.pole_pairs, F.psi_d_wb, F.psi_q_wb, id, iq);
    r.t_d = k * (L.ldd_h * iq - F.psi_q_wb - L.ldq_h * id);
    r.t_q = physics::TorqueSlopeIq(lim.pole_pairs, F.psi_d_wb, L.ldq_h, L.lqq_h, id, iq);
    r.c = ud * ud + uq * uq - u2;
    r.g_d = 2 * (ud * (rs - we * L.ldq_h) + uq * we * L.ldd_h);
    r.g_q = 2 * (-ud * we * L.lqq_h + uq * (rs + we * L.ldq_h));
    return r;
  };
  auto cross = [](const Local& a) { return a.t_d * a.g_q - a.t_q * a.g_d; };
  const double h = 1e-6 * lim.i_max_a;
  double id = id0, iq = iq0;
  for (int it = 0; it < 20; ++it) {
    const Local a = at(id, iq);
    const double f1 = a.c, f2 = cross(a);
    const double gn = std::hypot(a.g_d, a.g_q);
    if (std::abs(f1) <= 1e-13 * u2 && std::abs(f2) <= 1e-10 * std::hypot(a.t_d, a.t_q) * gn) {
      const double l = s * (a.t_d * a.g_d + a.t_q * a.g_q) / (gn * gn);
      if (!(s * iq > 0 && id >= -lim.i_max_a && id <= 0 && std::hypot(id, iq) < lim.i_max_a * (1 - 1e-6) && l > 0)) {
        return false;
      }
      out->t = s * a.torque;
      out->direct = true;
      out->id = id;
      out->iq = iq;
      return true;
    }
    const Local b = at(id + h, iq), c = at(id, iq + h);
    const double f2_d = (cross(b) - f2) / h, f2_q = (cross(c) - f2) / h;
    if (!DampedNewtonStep(a.g_d, a.g_q, f2_d, f2_q, f1, f2, 0.25 * lim.i_max_a, &id, &iq)) return false;
  }
  return false;
}

}  // namespace internal

}  // namespace fluxcal::tables
