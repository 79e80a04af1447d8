#include "simulation/plant.h"
#include "physics/inverter.h"

namespace fluxcal::sim {

void DeadTimeError(const PlantModel& m, double ia, double ib, double ic, double* ua, double* ub) {
  if (m.dead_time_s == 0.0 && m.threshold_v == 0.0) { *ua = *ub = 0; return; }
  const double k = -((m.dead_time_s / m.ts_s) * m.udc_v + m.threshold_v);
  const AlphaBeta e = physics::SoftSignVector(ia, ib, ic, k, m.dead_time_i_th_a);
  *ua = e.alpha;
  *ub = e.beta;
}

void Derivative(const PlantModel& m, const State& x, double th, double we, double ual, double ube,
                double* dpsd, double* dpsq, double* dlpd, double* dlpq, Vec2* i_out, Vec2* i_terminal) {
  const Vec2 i = m.Current(x.psd, x.psq, th, x.i);
  *i_out = i;
  const double c = std::cos(th), s = std::sin(th);
  // Phase currents for the dead-time error.
  double ial, ibe;
  InverseParkCs(i.d, i.q, c, s, &ial, &ibe);
  const Phases ph = InverseClarke(ial, ibe);
  double eal, ebe;
  DeadTimeError(m, ph.a, ph.b, ph.c, &eal, &ebe);
  // Per-phase extra resistance (a bad joint, the switches' slope r_on): its
  // drop (dr_x + r_on) i_x, back in alpha-beta.
  const AlphaBeta dr = Clarke((m.dr_a_ohm + m.slope_ohm) * ph.a, (m.dr_b_ohm + m.slope_ohm) * ph.b,
                              (m.dr_c_ohm + m.slope_ohm) * ph.c);
  const double ua = m.voltage_gain * ual + eal - dr.alpha, ub = m.voltage_gain * ube + ebe - dr.beta;
  double ud, uq;
  ParkCs(ua, ub, c, s, &ud, &uq);
  const double k = 1.0 / (1.0 + m.rs_ohm * m.g_fe_s);
  const double ed = k * (ud - m.rs_ohm * i.d - m.r_hf_ohm * (i.d - x.lpd));
  const double eq = k * (uq - m.rs_ohm * i.q - m.r_hf_ohm * (i.q - x.lpq));
  *dpsd = ed + we * x.psq;
  *dpsq = eq - we * x.psd;
  if (i_terminal != nullptr) *i_terminal = Vec2{i.d + m.g_fe_s * ed, i.q + m.g_fe_s * eq};
  *dlpd = m.hf_corner_rad_s * (i.d - x.lpd);
  *dlpq = m.hf_corner_rad_s * (i.q - x.lpq);
}

void Rk4(const PlantModel& m, State* x, double th0, double we, double h, double ual, double ube) {
  double k1[4], k2[4], k3[4], k4[4];
  Vec2 i;
  auto eval = [&](const State& s, double th, double* k) {
    Derivative(m, s, th, we, ual, ube, &k[0], &k[1], &k[2], &k[3], &i);
  };
  auto add = [&](const State& s, const double* k, double f) {
    State r = s;
    r.psd += f * k[0]; r.psq += f * k[1]; r.lpd += f * k[2]; r.lpq += f * k[3];
    r.i = i;
    return r;
  };
  eval(*x, th0, k1);
  x->i = i;
  eval(add(*x, k1, 0.5 * h), th0 + 0.5 * h * we, k2);
  eval(add(*x, k2, 0.5 * h), th0 + 0.5 * h * we, k3);
  eval(add(*x, k3, h), th0 + h * we, k4);
  x->psd += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]);
  x->psq += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]);
  x->lpd += h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]);
  x->lpq += h / 6 * (k1[3] + 2 * k2[3] + 2 * k3[3] + k4[3]);
  x->i = m.Current(x->psd, x->psq, th0 + h * we, i);
  x->i_term = x->i;
  if (m.g_fe_s != 0.0) {
    // The terminal current at the end of the step, under the voltage held
    // over it (what a sensor sampling before the next command reads).
    double d[4];
    Vec2 im;
    Derivative(m, *x, th0 + h * we, we, ual, ube, &d[0], &d[1], &d[2], &d[3], &im, &x->i_term);
  }
}

}  // namespace fluxcal::sim
