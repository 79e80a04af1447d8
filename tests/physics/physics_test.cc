// The physics kernel against first principles: torque from the co-energy,
// the frames' conventions and round trips, speed conversions, the inverter
// soft sign and the controller timing, and that every template takes a
// ceres::Jet.
#include <cmath>
#include <array>
#include <complex>
#include <vector>

#include <ceres/jet.h>
#include <gtest/gtest.h>

#include "physics/constants.h"
#include "physics/delay.h"
#include "physics/frames.h"
#include "physics/hf.h"
#include "physics/hf_orbit.h"
#include "physics/inverter.h"
#include "physics/speed.h"
#include "physics/torque.h"

namespace fluxcal::physics {
namespace {

// A conservative, saturating, cross-coupled dq magnetic model: its
// co-energy W(id, iq) and the fluxes psi = grad W.
struct AnalyticFlux {
  double psi_pm = 0.08, ld = 3e-4, lq = 7e-4, a = 2e-8, c = 4e-6;
  double CoEnergy(double id, double iq) const {
    return psi_pm * id + 0.5 * ld * id * id + 0.5 * lq * iq * iq - 0.25 * a * iq * iq * iq * iq + c * id * iq * iq;
  }
  double PsiD(double id, double iq) const { return psi_pm + ld * id + c * iq * iq; }
  double PsiQ(double id, double iq) const { return lq * iq - a * iq * iq * iq + 2 * c * id * iq; }
};

// dq currents of fixed phase currents seen from a rotor at theta_e.
void Dq(const Phases<double>& i, double theta, double* id, double* iq) {
  const AlphaBeta<double> ab = Clarke(i.a, i.b, i.c);
  Park(ab.alpha, ab.beta, theta, id, iq);
}

TEST(Torque, EqualsTheCoEnergyDerivativeAtConstantPhaseCurrents) {
  // Phase co-energy W'_abc(i_abc, theta) = sum_x int psi_x di_x
  // = 1.5 W(id, iq) for amplitude-invariant dq; T = dW'/dtheta_m
  // = p dW'/dtheta_e at constant phase currents.
  const AnalyticFlux f;
  const int p = 4;
  for (double theta : {0.3, 1.9, -2.4}) {
    for (auto [idr, iqr] : {std::pair{-40.0, 60.0}, std::pair{10.0, -25.0}, std::pair{-80.0, 120.0}}) {
      double al, be;
      InversePark(idr, iqr, theta, &al, &be);
      const Phases<double> i = InverseClarke(al, be);
      const double h = 1e-5;
      double id1, iq1, id2, iq2;
      Dq(i, theta + h, &id1, &iq1);
      Dq(i, theta - h, &id2, &iq2);
      const double t_coenergy = p * 1.5 * (f.CoEnergy(id1, iq1) - f.CoEnergy(id2, iq2)) / (2 * h);
      const double t = ElectromagneticTorque(p, f.PsiD(idr, iqr), f.PsiQ(idr, iqr), idr, iqr);
      EXPECT_NEAR(t, t_coenergy, 1e-6 * (1 + std::abs(t))) << theta << " " << idr << " " << iqr;
    }
  }
}

// The transducer's loss opposes the rotation at any speed sign, is zero at
// standstill, and is linear in its two parameters (a Jet sees T_f with
// slope sign(n) and b with slope |w_m| sign(n) = w_m).
TEST(Torque, MechanicalLossOpposesTheRotation) {
  const double w = RpmToMechanicalRadS(1500.0);
  EXPECT_NEAR(MechanicalLossTorque(0.1, 1e-3, 1500.0), 0.1 + 1e-3 * w, 1e-15);
  EXPECT_NEAR(MechanicalLossTorque(0.1, 1e-3, -1500.0), -(0.1 + 1e-3 * w), 1e-15);
  EXPECT_EQ(MechanicalLossTorque(0.1, 1e-3, 0.0), 0.0);
  using J = ceres::Jet<double, 2>;
  const J t = MechanicalLossTorque(J(0.1, 0), J(1e-3, 1), -1500.0);
  EXPECT_NEAR(t.v[0], -1.0, 1e-15);
  EXPECT_NEAR(t.v[1], -w, 1e-12);
}

TEST(Torque, SlopeIsTheDerivativeAlongIq) {
  const AnalyticFlux f;
  const int p = 3;
  const double id = -30, iq = 50, h = 1e-4;
  const double num = (ElectromagneticTorque(p, f.PsiD(id, iq + h), f.PsiQ(id, iq + h), id, iq + h) -
                      ElectromagneticTorque(p, f.PsiD(id, iq - h), f.PsiQ(id, iq - h), id, iq - h)) / (2 * h);
  const double ldq = 2 * f.c * iq, lqq = f.lq - 3 * f.a * iq * iq + 2 * f.c * id;
  EXPECT_NEAR(TorqueSlopeIq(p, f.PsiD(id, iq), ldq, lqq, id, iq), num, 1e-6);
}

TEST(Frames, ClarkeIsAmplitudeInvariantAndDropsZeroSequence) {
  const double peak = 7.5, phi = 0.4;
  const AlphaBeta<double> ab =
      Clarke(peak * std::cos(phi), peak * std::cos(phi - 2 * kPi / 3), peak * std::cos(phi + 2 * kPi / 3));
  EXPECT_NEAR(std::hypot(ab.alpha, ab.beta), peak, 1e-12);
  EXPECT_NEAR(std::atan2(ab.beta, ab.alpha), phi, 1e-12);
  const AlphaBeta<double> shifted =
      Clarke(peak * std::cos(phi) + 2, peak * std::cos(phi - 2 * kPi / 3) + 2, peak * std::cos(phi + 2 * kPi / 3) + 2);
  EXPECT_NEAR(shifted.alpha, ab.alpha, 1e-12);
  EXPECT_NEAR(shifted.beta, ab.beta, 1e-12);
}

TEST(Frames, RoundTrips) {
  const Phases<double> ph = InverseClarke(3.0, -1.25);
  EXPECT_NEAR(ph.a + ph.b + ph.c, 0.0, 1e-12);
  const AlphaBeta<double> ab = Clarke(ph.a, ph.b, ph.c);
  EXPECT_NEAR(ab.alpha, 3.0, 1e-12);
  EXPECT_NEAR(ab.beta, -1.25, 1e-12);
  double d, q, al, be;
  Park(3.0, -1.25, 0.9, &d, &q);
  InversePark(d, q, 0.9, &al, &be);
  EXPECT_NEAR(al, 3.0, 1e-12);
  EXPECT_NEAR(be, -1.25, 1e-12);
  // Park is the rotation by -theta: a vector at angle theta is pure d.
  Park(std::cos(0.9), std::sin(0.9), 0.9, &d, &q);
  EXPECT_NEAR(d, 1.0, 1e-12);
  EXPECT_NEAR(q, 0.0, 1e-12);
  EXPECT_NEAR(WrapAngle(-0.5), 2 * kPi - 0.5, 1e-12);
}

TEST(Speed, Conversions) {
  EXPECT_NEAR(RpmToElectricalRadS(1500.0, 4), 2 * kPi * 100, 1e-9);   // 1500 rpm x 4 pp = 100 Hz
  EXPECT_NEAR(ElectricalRadSToRpm(RpmToElectricalRadS(1234.5, 3), 3), 1234.5, 1e-9);
  EXPECT_NEAR(RpmToMechanicalRadS(60.0), 2 * kPi, 1e-12);
  EXPECT_NEAR(MechanicalAngle(0.5, 2, 4), (0.5 + 4 * kPi) / 4, 1e-12);
}

TEST(Inverter, SoftSignAndItsMeanOverARamp) {
  EXPECT_NEAR(SoftSign(100.0, 1.0), 1.0, 1e-12);
  EXPECT_NEAR(SoftSign(-100.0, 1.0), -1.0, 1e-12);
  EXPECT_NEAR(DeadTimePhaseError(50.0, 1e-6, 1e-4, 300.0, 0.5, 1.0), -(0.01 * 300 + 0.5), 1e-9);
  const double i0 = -1.3, i1 = 0.9, ith = 0.7;
  const int n = 200000;
  double mean = 0;
  for (int k = 0; k < n; ++k) mean += std::tanh((i0 + (i1 - i0) * (k + 0.5) / n) / ith) / n;
  EXPECT_NEAR(MeanSoftSign(i0, i1, ith), mean, 1e-8);
  EXPECT_NEAR(MeanSoftSign(0.2, 0.2, ith), std::tanh(0.2 / ith), 1e-12);
  // Far from zero current the vector is the hard-sign one: gain x Clarke(sign).
  const AlphaBeta<double> e = SoftSignVector(30.0, -12.0, -18.0, 2.0, 0.5);
  EXPECT_NEAR(e.alpha, 2.0 * 4.0 / 3.0, 1e-9);
  EXPECT_NEAR(e.beta, 0.0, 1e-9);
}

TEST(Delay, ZohGainIsTheMeanOfTheRotatingVectorOverAPeriod) {
  const double w = 2 * kPi * 700, T = 1e-4;
  std::complex<double> mean = 0;
  const int n = 100000;
  for (int k = 0; k < n; ++k) mean += std::polar(1.0, w * T * ((k + 0.5) / n - 0.5)) / double(n);
  EXPECT_NEAR(std::abs(mean), ZohGain(w, T), 1e-9);
  EXPECT_EQ(ZohGain(0.0, T), 1.0);
  EXPECT_DOUBLE_EQ(ControlDelayAngle(w, T), 1.5 * w * T);
}

TEST(Delay, StaircaseDelayOfTheSampledCurrent) {
  const double w = 2 * kPi * 500, T = 1e-4;
  // Whole periods: the pure rotation e^{-j w n T}.
  EXPECT_NEAR(std::abs(StaircaseDelay(w, 2 * T, T) - std::polar(1.0, -2 * w * T)), 0.0, 1e-12);
  // Half a period: the mean of two corners, magnitude cos(w T / 2), phase -w T / 2.
  const std::complex<double> h = StaircaseDelay(w, 0.5 * T, T);
  EXPECT_NEAR(std::abs(h), std::cos(0.5 * w * T), 1e-12);
  EXPECT_NEAR(std::arg(h), -0.5 * w * T, 1e-12);
}

TEST(Hf, PhasorsSolveE1E2) {
  // Without iron loss the branch is j w L: S = j w (Ldd + Lqq)/2,
  // D = j w ((Ldd - Lqq)/2 + j Ldq); the phasors must satisfy (E1)-(E2).
  const double ldd = 1.8e-4, lqq = 3.6e-4, ldq = 1e-5, r = 0.02, wi = 2 * kPi * 500;
  const std::complex<double> j(0, 1), v(5.0, 0.3), vn(0.2, -0.1);
  for (double we : {0.0, 400.0}) {
    std::complex<double> i0, i1;
    SolveHfPhasors(ldd, lqq, ldq, r, v, vn, wi, we, 0.0, &i0, &i1);
    const double w2 = 2 * we - wi;
    const std::complex<double> s = 0.5 * (ldd + lqq), d(0.5 * (ldd - lqq), ldq);
    const std::complex<double> e1 = r * i0 + j * wi * (s * i0 + d * std::conj(i1));
    const std::complex<double> e2 = r * i1 + j * w2 * (s * i1 + d * std::conj(i0));
    EXPECT_NEAR(std::abs(e1 - v), 0.0, 1e-9 * std::abs(v)) << we;
    EXPECT_NEAR(std::abs(e2 - vn), 0.0, 1e-9 * std::abs(v)) << we;
  }
  // The paper's eq. (8) at standstill, R = 0, Ldq = 0: |I0| + |I1| = V / (w Ldd).
  std::complex<double> i0, i1;
  SolveHfPhasors(ldd, lqq, 0.0, 0.0, v, 0.0, wi, 0.0, 0.0, &i0, &i1);
  EXPECT_NEAR(std::abs(i0) + std::abs(i1), std::abs(v) / (wi * ldd), 1e-9 * std::abs(i0));
  EXPECT_NEAR(std::abs(i0) - std::abs(i1), std::abs(v) / (wi * lqq), 1e-9 * std::abs(i0));
}

TEST(Hf, IronLossBranchOfAnIsotropicMachine) {
  // L = l I: M = j w l / (1 + j w g l), S = M, D = 0.
  const double l = 2e-4, w = 2 * kPi * 800, g = 0.05;
  std::complex<double> s, d;
  HfBranch(l, l, 0.0, w, g, &s, &d);
  const std::complex<double> j(0, 1), m = j * w * l / (1.0 + j * w * g * l);
  EXPECT_NEAR(std::abs(s - m), 0.0, 1e-12 * std::abs(m));
  EXPECT_NEAR(std::abs(d), 0.0, 1e-12 * std::abs(m));
}

TEST(Jet, EveryTemplateDifferentiates) {
  using J = ceres::Jet<double, 2>;
  const J psi_pm(0.08, 0), iq_j(60.0, 1);
  // T = 1.5 p (psi_d iq - psi_q id) with psi_d = psi_pm: dT/dpsi_pm = 1.5 p iq.
  const J t = ElectromagneticTorque(4, psi_pm + J(1e-3), J(0.02), J(-10.0), iq_j);
  EXPECT_NEAR(t.v[0], 1.5 * 4 * 60.0, 1e-12);
  EXPECT_NEAR(t.v[1], 1.5 * 4 * (0.081), 1e-12);   // dT/diq = 1.5 p psi_d
  const J th(0.7, 0);
  J d, q;
  const AlphaBeta<J> ab = Clarke(J(1.0, 0), J(-0.3, 1), J(-0.7));
  Park(ab.alpha, ab.beta, th, &d, &q);
  EXPECT_NEAR(d.a, std::cos(0.7) * ab.alpha.a + std::sin(0.7) * ab.beta.a, 1e-12);
  EXPECT_NEAR(ab.beta.v[1], 1 / kSqrt3, 1e-12);
  EXPECT_NEAR(ab.alpha.v[1], -1.0 / 3.0, 1e-12);
  const Phases<J> ph = InverseClarke(J(1.0, 0), J(2.0, 1));
  EXPECT_NEAR(ph.b.v[1], 0.5 * kSqrt3, 1e-12);
  J al, be;
  InversePark(J(1.0), J(0.0), J(0.3, 0), &al, &be);
  EXPECT_NEAR(be.v[0], std::cos(0.3), 1e-12);   // d beta / d theta
  const J we = RpmToElectricalRadS(J(1500.0, 0), 4);
  EXPECT_NEAR(we.v[0], 4 * 2 * kPi / 60, 1e-12);
  EXPECT_NEAR(ElectricalRadSToRpm(we, 4).v[0], 1.0, 1e-12);
  EXPECT_NEAR(SoftSign(J(0.0, 0), 2.0).v[0], 0.5, 1e-12);
  EXPECT_NEAR(DeadTimePhaseError(J(0.0, 0), 1e-6, 1e-4, 300.0, 0.0, 1.0).v[0], -3.0, 1e-12);
  const J g = ZohGain(J(2 * kPi * 500, 0), 1e-4);
  const double x = 0.5 * 2 * kPi * 500 * 1e-4;
  EXPECT_NEAR(g.v[0], 0.5e-4 * (std::cos(x) / x - std::sin(x) / (x * x)), 1e-12);
  EXPECT_NEAR(MechanicalAngle(J(0.5, 0), 1, 4).v[0], 0.25, 1e-12);
}

}  // namespace
}  // namespace fluxcal::physics

// The describing function over the HF orbit (physics/hf_orbit.h).
namespace fluxcal::physics {
namespace {

// A linear machine, cross-coupled: the injection measures its inductance
// exactly, at any amplitude.
TEST(HfOrbit, LinearMachineMeasuresItsInductance) {
  const double ldd = 2e-4, lqq = 5e-4, ldq = -3e-5;
  auto map = [&](double id, double iq, double* psi, double* l) {
    psi[0] = 0.05 + ldd * id + ldq * iq;
    psi[1] = ldq * id + lqq * iq;
    l[0] = ldd; l[1] = lqq; l[2] = ldq;
  };
  std::vector<std::array<double, 2>> orbit;
  ASSERT_TRUE(HfOrbit(map, -40.0, 60.0, 2e-3, &orbit));
  std::array<std::vector<std::array<double, 2>>, 3> w;
  ASSERT_TRUE(DescribingWeights(orbit, &w));
  double mean_d = 0, mean_q = 0, l[3] = {0, 0, 0};
  for (size_t k = 0; k < orbit.size(); ++k) {
    double psi[2], jac[3];
    map(orbit[k][0], orbit[k][1], psi, jac);
    for (int c = 0; c < 3; ++c) l[c] += w[c][k][0] * psi[0] + w[c][k][1] * psi[1];
    mean_d += orbit[k][0] / orbit.size();
    mean_q += orbit[k][1] / orbit.size();
  }
  EXPECT_NEAR(mean_d, -40.0, 1e-9);
  EXPECT_NEAR(mean_q, 60.0, 1e-9);
  EXPECT_NEAR(l[0], ldd, 1e-12);
  EXPECT_NEAR(l[1], lqq, 1e-12);
  EXPECT_NEAR(l[2], ldq, 1e-12);
}

// One saturating axis, psi_d = L x + c x^2/2 + d x^3/6 (x = id - i0): the
// measured Ldd is L + d a^2/8 - c^2 a^2/(8 L) to O(a^4) (the series in the
// header), a = rho / L (1, 2, 4 A here); the linear q axis is measured as
// it is.
TEST(HfOrbit, SaturatingAxisFollowsTheSeries) {
  const double L = 1e-3, c = -5e-5, d = -5e-6, lq = 2e-3, i0 = -30.0;
  auto map = [&](double id, double iq, double* psi, double* l) {
    const double x = id - i0;
    psi[0] = 0.1 + L * x + c * x * x / 2 + d * x * x * x / 6;
    psi[1] = lq * iq;
    l[0] = L + c * x + d * x * x / 2; l[1] = lq; l[2] = 0.0;
  };
  for (double rho : {1e-3, 2e-3, 4e-3}) {
    std::vector<std::array<double, 2>> orbit;
    ASSERT_TRUE(HfOrbit(map, i0, 10.0, rho, &orbit));
    std::array<std::vector<std::array<double, 2>>, 3> w;
    ASSERT_TRUE(DescribingWeights(orbit, &w));
    double l[3] = {0, 0, 0};
    for (size_t k = 0; k < orbit.size(); ++k) {
      double psi[2], jac[3];
      map(orbit[k][0], orbit[k][1], psi, jac);
      for (int m = 0; m < 3; ++m) l[m] += w[m][k][0] * psi[0] + w[m][k][1] * psi[1];
    }
    const double a = rho / L;
    const double series = d * a * a / 8 - c * c * a * a / (8 * L);
    // The O(a^4) remainder: ~1 % of the correction at a = 1 A, growing as a^2.
    EXPECT_NEAR(l[0] - L, series, (rho < 1.5e-3 ? 0.01 : 0.1) * std::abs(series)) << "rho " << rho;
    EXPECT_GT(std::abs(series), 5e-4 * L) << "the case must test something";
    EXPECT_NEAR(l[1], lq, 1e-12);
    EXPECT_NEAR(l[2], 0.0, 1e-12);
  }
}

}  // namespace
}  // namespace fluxcal::physics
