#include "simulation/trait_motor.h"

#include <algorithm>
#include <cmath>

namespace fluxcal::sim {
namespace {

// S'(x) = Ls x + (L0 - Ls) I tanh(x / I).
double S1(double x, double l0, double ls, double i) { return ls * x + (l0 - ls) * i * std::tanh(x / i); }
// S(x) with ln cosh(u) = |u| + ln(1 + e^{-2|u|}) - ln 2 (no overflow).
double S0(double x, double l0, double ls, double i) {
  const double ax = std::abs(x / i);
  return 0.5 * ls * x * x + (l0 - ls) * i * i * (ax + std::log1p(std::exp(-2 * ax)) - std::log(2.0));
}

}  // namespace

FluxLinkage TraitMotor::Flux(double id, double iq, double) const {
  const MotorTraits& t = t_;
  // Cross term -cross G(id) H(iq) (see the header); G' and H' by S1.
  const double g = S0(id, 1.0, 0.2, t.id_knee_a) / t.id_knee_a, g1 = S1(id, 1.0, 0.2, t.id_knee_a) / t.id_knee_a;
  const double h = S0(iq, 1.0, 0.3, t.iq_knee_a) / t.iq_knee_a, h1 = S1(iq, 1.0, 0.3, t.iq_knee_a) / t.iq_knee_a;
  const double ox = t.id_knee_a;
  const double r2 = t.bump_r_a * t.bump_r_a, eb = std::exp(-(id * id + iq * iq) / r2);
  FluxLinkage f;
  f.psi_d_wb = t.psi_pm_wb + S1(id, t.ld0_h, t.lds_h, t.id_knee_a) - t.cross_h * g1 * h +
               t.psi_q_offset_wb * std::cos(id / ox) * iq / ox - t.bump_wb_a * 2 * id / r2 * eb;
  f.psi_q_wb = S1(iq, t.lq0_h, t.lqs_h, t.iq_knee_a) - t.cross_h * g * h1 +
               t.psi_q_offset_wb * std::sin(id / ox) - t.bump_wb_a * 2 * iq / r2 * eb;
  return f;
}

DifferentialInductance TraitMotor::Inductance(double id, double iq, double) const {
  const double h = 1e-4 * std::min(t_.id_knee_a, t_.iq_knee_a);
  const FluxLinkage a = Flux(id + h, iq), b = Flux(id - h, iq), c = Flux(id, iq + h), e = Flux(id, iq - h);
  DifferentialInductance l;
  l.ldd_h = (a.psi_d_wb - b.psi_d_wb) / (2 * h);
  l.lqq_h = (c.psi_q_wb - e.psi_q_wb) / (2 * h);
  // Reciprocal by construction: the mean of the two cross derivatives.
  l.ldq_h = 0.5 * ((c.psi_d_wb - e.psi_d_wb) + (a.psi_q_wb - b.psi_q_wb)) / (2 * h);
  return l;
}

namespace {

// Parameters stated for a machine of `i_ref` amperes, scaled to the current
// range m: inductances scale as 1/m and fluxes stay, so every map keeps its
// shape and its flux level.
MotorTraits Scaled(MotorTraits t, double i_ref, double m, double flux_scale) {
  const double k = i_ref / m;   // L -> L k, I -> I / k
  const double f = flux_scale;  // psi -> psi f, L -> L f
  t.psi_pm_wb *= f;
  t.ld0_h *= k * f; t.lds_h *= k * f; t.lq0_h *= k * f; t.lqs_h *= k * f;
  t.id_knee_a /= k; t.iq_knee_a /= k; t.bump_r_a /= k;
  t.cross_h *= k * f;
  t.psi_q_offset_wb *= f;
  t.bump_wb_a *= f / k;
  return t;
}

// Every stated motor and the current it is stated for: the real-like
// machines (parameters stated for a 200-400 A machine) first, then the
// other kinds. Both lists scale the same way, so they are one table.
struct StatedMotor {
  MotorTraits traits;
  double i_ref_a;
  bool real_like;
};

std::vector<MotorTraits> ScaledMotors(bool real_like, double m, double flux_scale) {
  const StatedMotor stated[] = {
      {{"pm-syrm", 0.04, 0.6e-3, 0.35e-3, 80, 4.0e-3, 0.8e-3, 40, 3e-5, 0, 0, 1}, 200, true},
      {{"ipm-bridge", 0.09, 0.25e-3, 0.15e-3, 250, 1.5e-3, 0.15e-3, 60, 2e-5, 0, 0, 1}, 400, true},
      {{"psi-q-offset", 0.08, 0.3e-3, 0.18e-3, 200, 0.8e-3, 0.3e-3, 150, 1e-4, 0.015, 0, 1}, 300, true},
      {{"negative-slope", 0.08, 0.3e-3, 0.18e-3, 200, 0.8e-3, 0.3e-3, 150, 1e-4, 0, 0.6, 60}, 300, true},
      {{"syrm", 0.0, 0.5e-3, 0.3e-3, 80, 5e-3, 0.6e-3, 30, 5e-5, 0, 0, 1}, 200, false},
      {{"spm", 0.1, 0.2e-3, 0.15e-3, 400, 0.21e-3, 0.15e-3, 300, 5e-6, 0, 0, 1}, 300, false},
      {{"strong-cross", 0.08, 0.3e-3, 0.18e-3, 200, 0.8e-3, 0.3e-3, 150, 1.5e-4, 0, 0, 1}, 300, false},
      {{"deep-sat", 0.06, 0.4e-3, 0.08e-3, 60, 1.2e-3, 0.15e-3, 50, 1e-5, 0, 0, 1}, 300, false},
  };
  std::vector<MotorTraits> out;
  for (const StatedMotor& s : stated) {
    if (s.real_like == real_like) out.push_back(Scaled(s.traits, s.i_ref_a, m, flux_scale));
  }
  return out;
}

}  // namespace

std::vector<MotorTraits> RealLikeMotors(double m, double flux_scale) { return ScaledMotors(true, m, flux_scale); }

std::vector<MotorTraits> OtherKindMotors(double m, double flux_scale) { return ScaledMotors(false, m, flux_scale); }

}  // namespace fluxcal::sim
