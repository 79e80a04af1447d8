// Accuracy of the HF demodulators and the inductance inversion against
// analytic synthetic currents with known Ldd, Lqq, Ldq, R, angle and speed.
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "gtest/gtest.h"
#include "identification/demod.h"
#include "identification/inductance.h"

namespace fluxcal::ident {
namespace {

using Complex = std::complex<double>;
constexpr double kPi = std::numbers::pi;

struct Truth {
  double ldd_h = 0.18e-3, lqq_h = 0.37e-3, ldq_h = 0.0, r_ohm = 0.012;
  double speed_rpm = 0.0, theta0_rad = 0.7;
  int pole_pairs = 4;
  double id_a = -20, iq_a = 40;
  double noise_a = 0.0;      // per real component
  double v_cmd_v = 5.0;
  // The command's negative sequence (a bench loop answering I1 at speed).
  Complex v_neg_cmd_v = 0.0;
  // Deterministic current components off the regressors' frequencies: the
  // orbit's third harmonic (at 3 w_i) and the fundamental's fifth (at
  // -5 theta_e), amplitudes in A.
  double third_hf_a = 0.0, fifth_fundamental_a = 0.0;
};

struct Signals {
  std::vector<double> ia, ib, ic, th, ua, ub;
  double fs = 10000.0, fi = 500.0;
  PhaseSamples View() const {
    return PhaseSamples{ia.data(), ib.data(), ic.data(), th.data(), ia.size(), fs, fi};
  }
};

// Exact stationary-frame solution of u = R i + d psi/dt for a machine with
// constant differential inductance, rotating injection and a dq-constant
// fundamental current (eqs. (E1)-(E2) in identification/inductance.h).
Signals Make(const Truth& t, size_t n, std::mt19937_64* rng = nullptr) {
  Signals s;
  const double w = 2 * kPi * s.fi;
  const double we = t.speed_rpm * t.pole_pairs * 2 * kPi / 60.0;
  const Complex v_cmd = std::polar(t.v_cmd_v, 0.3);
  Complex i0, i1;
  PredictPhasors(t.ldd_h, t.lqq_h, t.ldq_h, t.r_ohm, EffectiveVoltage(v_cmd, w, s.fs),
                 EffectiveVoltage(t.v_neg_cmd_v, 2 * we - w, s.fs), w, we, &i0, &i1);
  std::normal_distribution<double> nd(0.0, t.noise_a);
  for (size_t k = 0; k < n; ++k) {
    const double tk = static_cast<double>(k) / s.fs;
    const double th = t.theta0_rad + we * tk;
    const Complex i = i0 * std::polar(1.0, w * tk) + i1 * std::polar(1.0, 2 * th - w * tk) +
                      Complex(t.id_a, t.iq_a) * std::polar(1.0, th) +
                      t.third_hf_a * std::polar(1.0, 3 * w * tk + 0.4) +
                      t.fifth_fundamental_a * std::polar(1.0, -5 * th + 1.3);
    double ar = i.real(), ai = i.imag();
    if (rng) { ar += nd(*rng); ai += nd(*rng); }
    // Inverse amplitude-invariant Clarke (zero sequence 0).
    s.ia.push_back(ar);
    s.ib.push_back(-0.5 * ar + std::sqrt(3.0) / 2 * ai);
    s.ic.push_back(-0.5 * ar - std::sqrt(3.0) / 2 * ai);
    s.th.push_back(std::remainder(th, 2 * kPi));
    const Complex u = v_cmd * std::polar(1.0, w * tk) + t.v_neg_cmd_v * std::polar(1.0, 2 * th - w * tk) +
                      Complex(1.0, 2.0) * std::polar(1.0, th);
    s.ua.push_back(u.real());
    s.ub.push_back(u.imag());
  }
  return s;
}

// `read_negative_sequence` false solves (E2) with Vn = 0, as the paper does.
HfInductance IdentifyLsq(const Signals& s, bool read_negative_sequence = true) {
  auto e = LsqDemodulate(s.View());
  EXPECT_TRUE(e.ok()) << e.status();
  auto v = FitCommandVoltage(s.ua.data(), s.ub.data(), s.th.data(), s.ia.size(), s.fs, s.fi);
  EXPECT_TRUE(v.ok());
  const double w = 2 * kPi * s.fi;
  const Complex vn = read_negative_sequence ? EffectiveVoltage(v->v_neg_cmd_v, 2 * e->w_e_rad_s - w, s.fs) : 0.0;
  auto L = InductanceFromPhasors(e->i0_a, e->i1_a, EffectiveVoltage(v->v_cmd_v, w, s.fs), vn, w,
                                 e->w_e_rad_s, {e->var_i0_a2, e->var_i1_a2, e->cov_i0_i1_a2});
  EXPECT_TRUE(L.ok()) << L.status();
  return *L;
}

HfInductance IdentifyPaper(const Signals& s, bool compensate) {
  auto e = PaperDemodulate(s.View(), compensate);
  EXPECT_TRUE(e.ok()) << e.status();
  auto v = FitCommandVoltage(s.ua.data(), s.ub.data(), s.th.data(), s.ia.size(), s.fs, s.fi);
  const double w = 2 * kPi * s.fi;
  auto L = PaperInductance(e->i0_a, e->i1_a, std::abs(EffectiveVoltage(v->v_cmd_v, w, s.fs)), w);
  EXPECT_TRUE(L.ok()) << L.status();
  return *L;
}

double Rel(double got, double want) { return std::abs(got / want - 1.0); }

TEST(LsqDemodulator, NoiseFreeExactAtStandstill) {
  Truth t;
  t.ldq_h = 0.02e-3;
  const auto L = IdentifyLsq(Make(t, 1000));
  EXPECT_LT(Rel(L.ldd_h, t.ldd_h), 1e-6) << "Ldd " << L.ldd_h << " H, want " << t.ldd_h;
  EXPECT_LT(Rel(L.lqq_h, t.lqq_h), 1e-6) << "Lqq " << L.lqq_h << " H, want " << t.lqq_h;
  EXPECT_LT(Rel(L.ldq_h, t.ldq_h), 1e-6) << "Ldq " << L.ldq_h << " H, want " << t.ldq_h;
  EXPECT_LT(Rel(L.r_hf_ohm, t.r_ohm), 1e-5) << "R " << L.r_hf_ohm << " Ohm, want " << t.r_ohm;
}

TEST(LsqDemodulator, NoiseFreeExactAt1000Rpm) {
  Truth t;
  t.speed_rpm = 1000;
  t.ldq_h = -0.015e-3;
  const auto L = IdentifyLsq(Make(t, 1000));
  EXPECT_LT(Rel(L.ldd_h, t.ldd_h), 1e-6) << "Ldd " << L.ldd_h;
  EXPECT_LT(Rel(L.lqq_h, t.lqq_h), 1e-6) << "Lqq " << L.lqq_h;
  EXPECT_LT(Rel(L.ldq_h, t.ldq_h), 1e-6) << "Ldq " << L.ldq_h;
  EXPECT_LT(Rel(L.r_hf_ohm, t.r_ohm), 1e-5) << "R " << L.r_hf_ohm;
}

// A bench loop that answers the negative-sequence current at speed puts a
// voltage at w_2 = 2 w_e - w_i on the command (docs/identification.md,
// Sec. 8). Read from the command and put on (E2)'s left-hand side it is
// solved exactly; taken as zero (the paper's assumption) 0.4 V of it, 8 %
// of the injection, moves Ldd and Lqq by more than 1 %.
TEST(LsqDemodulator, NegativeSequenceCommandReadAndSolvedExactly) {
  for (double rpm : {0.0, 1000.0}) {
    Truth t;
    t.speed_rpm = rpm;
    t.ldq_h = 0.01e-3;
    t.v_neg_cmd_v = std::polar(0.4, -1.1);
    const Signals s = Make(t, 2000);
    const auto L = IdentifyLsq(s);
    EXPECT_LT(Rel(L.ldd_h, t.ldd_h), 1e-6) << rpm << " rpm: Ldd " << L.ldd_h;
    EXPECT_LT(Rel(L.lqq_h, t.lqq_h), 1e-6) << rpm << " rpm: Lqq " << L.lqq_h;
    EXPECT_LT(Rel(L.ldq_h, t.ldq_h), 1e-5) << rpm << " rpm: Ldq " << L.ldq_h;
    const auto wrong = IdentifyLsq(s, false);
    EXPECT_GT(std::max(Rel(wrong.ldd_h, t.ldd_h), Rel(wrong.lqq_h, t.lqq_h)), 0.01) << rpm << " rpm";
  }
}

TEST(PaperPipeline, StandstillWithinPointOnePercent) {
  Truth t;
  t.r_ohm = 0.0;  // eq. (8) assumes R = 0
  const auto L = IdentifyPaper(Make(t, 1000), true);
  EXPECT_LT(Rel(L.ldd_h, t.ldd_h), 1e-3) << "Ldd " << L.ldd_h << " H, want " << t.ldd_h;
  EXPECT_LT(Rel(L.lqq_h, t.lqq_h), 1e-3) << "Lqq " << L.lqq_h << " H, want " << t.lqq_h;
}

TEST(PaperPipeline, At1000RpmCompensationNeeded) {
  Truth t;
  t.r_ohm = 0.0;
  t.speed_rpm = 1000;
  const Signals s = Make(t, 1000);
  const auto comp = IdentifyPaper(s, true);
  const auto raw = IdentifyPaper(s, false);
  const double err_comp = std::max(Rel(comp.ldd_h, t.ldd_h), Rel(comp.lqq_h, t.lqq_h));
  const double err_raw = std::max(Rel(raw.ldd_h, t.ldd_h), Rel(raw.lqq_h, t.lqq_h));
  EXPECT_LT(err_comp, 2e-3) << "compensated: Ldd " << comp.ldd_h << " Lqq " << comp.lqq_h;
  // Without the exact gain of the cascade at 2 w_e - w_i the negative
  // sequence is mis-scaled; docs/identification.md gives the size.
  EXPECT_GT(err_raw, 5.0 * err_comp) << "uncompensated error " << err_raw;
  EXPECT_GT(err_raw, 0.01);
}

TEST(LsqDemodulator, CrossInductanceTenPercent) {
  Truth t;
  const double mean_l = 0.5 * (t.ldd_h + t.lqq_h);
  t.ldq_h = 0.1 * mean_l;
  t.noise_a = 0.05;
  std::mt19937_64 rng(11);
  const auto L = IdentifyLsq(Make(t, 1000, &rng));
  EXPECT_LT(std::abs(L.ldq_h - t.ldq_h), 0.01 * mean_l)
      << "Ldq " << L.ldq_h << " H, want " << t.ldq_h << " H";
}

// Cramer-Rao bound for a complex exponential's amplitude in white circular
// noise of variance sigma^2 = E|n|^2 (docs/identification.md, Sec. 4):
// var(I0) >= sigma^2 / N for N samples when the other regressors are
// orthogonal to it (whole injection periods).
TEST(LsqDemodulator, SpreadWithinCramerRaoBound) {
  Truth t;
  t.noise_a = 0.1;
  const size_t n = 1000, trials = 300;
  std::mt19937_64 rng(7);
  auto clean = LsqDemodulate(Make(t, n).View());
  ASSERT_TRUE(clean.ok());
  double se0 = 0, se1 = 0, reported = 0;
  for (size_t k = 0; k < trials; ++k) {
    const Signals s = Make(t, n, &rng);
    auto e = LsqDemodulate(s.View());
    ASSERT_TRUE(e.ok());
    se0 += std::norm(e->i0_a - clean->i0_a);
    se1 += std::norm(e->i1_a - clean->i1_a);
    reported += e->var_i0_a2;
  }
  const double sigma2 = 2 * t.noise_a * t.noise_a;  // both quadratures
  const double crb = sigma2 / static_cast<double>(n);
  const double std0 = std::sqrt(se0 / trials), std1 = std::sqrt(se1 / trials);
  EXPECT_LT(std0, 1.2 * std::sqrt(crb)) << "I0 spread " << std0 << " A, CRB " << std::sqrt(crb);
  EXPECT_LT(std1, 1.2 * std::sqrt(crb)) << "I1 spread " << std1 << " A, CRB " << std::sqrt(crb);
  // The standard error reported from the residual is honest (within 20%).
  EXPECT_NEAR(std::sqrt(reported / trials), std0, 0.2 * std0);
}

// Deterministic components away from the injection's frequencies (a
// saturating orbit's third harmonic, the fundamental's fifth at speed; at
// 600 rpm, 4 pole pairs, both whole cycles in the window) are orthogonal
// to the regressors: they move no estimate, and the standard errors, from
// the residual's density at each phasor's own frequency, stay those of
// the noise. From the residual's mean power, as before, they were 8 times
// too large here, and accurate rotating points of saturating machines read
// low_snr. (A component that is not whole cycles leaks into the estimate
// and into the density beside it alike.)
TEST(LsqDemodulator, StandardErrorsIgnoreHarmonicsAwayFromTheInjection) {
  Truth t;
  t.speed_rpm = 600;
  t.noise_a = 0.1;
  t.third_hf_a = 2.0;
  t.fifth_fundamental_a = 1.5;
  const size_t n = 1000, trials = 300;
  std::mt19937_64 rng(11);
  auto clean = LsqDemodulate(Make(t, n).View());
  ASSERT_TRUE(clean.ok());
  double se0 = 0, se1 = 0, reported0 = 0, reported1 = 0;
  for (size_t k = 0; k < trials; ++k) {
    auto e = LsqDemodulate(Make(t, n, &rng).View());
    ASSERT_TRUE(e.ok());
    se0 += std::norm(e->i0_a - clean->i0_a);
    se1 += std::norm(e->i1_a - clean->i1_a);
    reported0 += e->var_i0_a2;
    reported1 += e->var_i1_a2;
  }
  const double std0 = std::sqrt(se0 / trials), std1 = std::sqrt(se1 / trials);
  EXPECT_NEAR(std::sqrt(reported0 / trials), std0, 0.25 * std0);
  EXPECT_NEAR(std::sqrt(reported1 / trials), std1, 0.25 * std1);
  // The residual's mean power (the estimate before) would say 8 x.
  EXPECT_GT(std::sqrt((2 * t.noise_a * t.noise_a + t.third_hf_a * t.third_hf_a +
                       t.fifth_fundamental_a * t.fifth_fundamental_a) / n),
            5 * std0);
  // And the harmonics moved the estimate by less than a fifth of its noise
  // (the fundamental's drift regressor is not quite orthogonal to them).
  Truth plain = t;
  plain.third_hf_a = plain.fifth_fundamental_a = 0;
  auto exact = LsqDemodulate(Make(plain, n).View());
  ASSERT_TRUE(exact.ok());
  EXPECT_LT(std::abs(clean->i0_a - exact->i0_a), 0.2 * std0);
}

TEST(Inversion, ReducesToPaperEquation8) {
  // R = 0, Ldq = 0, standstill: (E1)-(E2) give the paper's closed form.
  const double w = 2 * kPi * 500, ldd = 0.18e-3, lqq = 0.37e-3;
  Complex i0, i1;
  PredictPhasors(ldd, lqq, 0, 0, Complex(5, 0), 0.0, w, 0, &i0, &i1);
  EXPECT_NEAR(5.0 / (w * (std::abs(i0) + std::abs(i1))), ldd, 1e-12);
  EXPECT_NEAR(5.0 / (w * (std::abs(i0) - std::abs(i1))), lqq, 1e-12);
  auto L = InductanceFromPhasors(i0, i1, Complex(5, 0), 0.0, w, 0);
  ASSERT_TRUE(L.ok());
  EXPECT_NEAR(L->ldd_h, ldd, 1e-12);
  EXPECT_NEAR(L->ldq_h, 0, 1e-15);
  EXPECT_NEAR(L->r_hf_ohm, 0, 1e-12);
}

TEST(Inversion, CrossInductanceFromNegativeSequencePhase) {
  // Ldq rotates the negative-sequence phasor relative to 2 theta_e:
  // arg(-I1) shifts by atan2(2 Ldq, Ldd - Lqq) at standstill (R = 0).
  const double w = 2 * kPi * 500, ldd = 0.18e-3, lqq = 0.37e-3, ldq = 0.03e-3;
  Complex i0, i1, j0, j1;
  PredictPhasors(ldd, lqq, 0, 0, Complex(5, 0), 0.0, w, 0, &i0, &i1);
  PredictPhasors(ldd, lqq, ldq, 0, Complex(5, 0), 0.0, w, 0, &j0, &j1);
  const double shift = std::arg(j1 / i1);
  const double want = std::atan2(2 * ldq, ldd - lqq) - std::atan2(0.0, ldd - lqq);
  EXPECT_NEAR(std::remainder(shift - want, 2 * kPi), 0.0, 1e-9);
}

}  // namespace
}  // namespace fluxcal::ident
