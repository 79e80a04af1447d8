// The twin's pieces against analytic truth: frames (Clarke/Park, rpm ->
// w_e, ZOH gain), the plant (RL step response, dead-time error, the
// DC-link sense gain's voltage scaling), and the effect catalogue.
#include <algorithm>
#include <cmath>
#include <complex>
#include <fstream>
#include <set>
#include <sstream>

#include "gtest/gtest.h"
#include "simulation/bench_effect.h"
#include "simulation/catalogue/catalogue_effect.h"
#include "simulation/effects.h"
#include "simulation/frames.h"
#include "simulation/plant.h"

namespace fluxcal::sim {
namespace {

TEST(Frames, ClarkeInverseClarkeAndPark) {
  // A balanced set of amplitude 10 A at angle 0.7 rad is the vector 10 e^{j 0.7}.
  const double a = 10 * std::cos(0.7), b = 10 * std::cos(0.7 - 2 * kPi / 3), c = 10 * std::cos(0.7 + 2 * kPi / 3);
  const AlphaBeta ab = Clarke(a, b, c);
  EXPECT_NEAR(ab.alpha, 10 * std::cos(0.7), 1e-12);
  EXPECT_NEAR(ab.beta, 10 * std::sin(0.7), 1e-12);
  const Phases ph = InverseClarke(ab.alpha, ab.beta);
  EXPECT_NEAR(ph.a, a, 1e-12);
  EXPECT_NEAR(ph.b, b, 1e-12);
  EXPECT_NEAR(ph.c, c, 1e-12);
  // The zero sequence drops out.
  EXPECT_NEAR(Clarke(a + 3, b + 3, c + 3).alpha, ab.alpha, 1e-12);
  // Park at the vector's own angle: all on d.
  double d, q;
  Park(ab.alpha, ab.beta, 0.7, &d, &q);
  EXPECT_NEAR(d, 10, 1e-12);
  EXPECT_NEAR(q, 0, 1e-12);
  double al, be;
  InversePark(d, q, 0.7, &al, &be);
  EXPECT_NEAR(al, ab.alpha, 1e-12);
  EXPECT_NEAR(be, ab.beta, 1e-12);
}

TEST(Frames, SpeedAndZeroOrderHold) {
  EXPECT_NEAR(RpmToElectricalRadS(1500, 4), 2 * kPi * 100, 1e-9);   // 1500 rpm x 4 pp = 100 Hz
  EXPECT_NEAR(ElectricalRadSToRpm(2 * kPi * 100, 4), 1500, 1e-9);
  // Mean of e^{j w t} over one period T, relative to its value at T/2.
  const double w = 2 * kPi * 500, T = 1e-4;
  std::complex<double> mean = 0;
  const int n = 100000;
  for (int k = 0; k < n; ++k) mean += std::polar(1.0, w * T * (k + 0.5) / n);
  mean /= static_cast<double>(n);
  EXPECT_NEAR(std::abs(mean), ZohGain(w, T), 1e-9);
  EXPECT_NEAR(std::arg(mean), w * T / 2, 1e-9);
  EXPECT_EQ(ZohGain(0.0, T), 1.0);
}

// A linear, unsaturated, non-salient winding: psi = psi_pm d + L i.
class LinearWinding : public MagneticModel {
 public:
  explicit LinearWinding(double l_h) : l_(l_h) {}
  FluxLinkage Flux(double id, double iq, double) const override { return {l_ * id, l_ * iq}; }
  DifferentialInductance Inductance(double, double, double) const override { return {l_, l_, 0.0}; }

 private:
  double l_;
};

PlantModel LinearPlant(const MagneticModel& model, double rs) {
  PlantModel m;
  ToArray(SaturationParams{}, m.p);
  m.map = &model;
  m.rs_ohm = rs;
  m.r_hf_ohm = 0;
  return m;
}

// RL step at standstill: i(t) = U/R (1 - e^{-t R/L}); and with the DC-link
// sense gain, the applied voltage is U / gain.
TEST(Plant, RlStepResponseAndDcLinkSenseGain) {
  const double l = 2e-4, r = 0.02, u = 1.0, h = 1e-5;
  LinearWinding w(l);
  for (double gain : {1.0, 0.95}) {
    PlantModel m = LinearPlant(w, r);
    m.voltage_gain = 1.0 / gain;
    State x{0, 0, 0, 0, Vec2{0, 0}};
    double t = 0;
    for (int k = 0; k < 2000; ++k) {
      Rk4(m, &x, 0.0, 0.0, h, u, 0.0);   // alpha = d at theta = 0
      t += h;
    }
    const double want = u / gain / r * (1 - std::exp(-t * r / l));
    EXPECT_NEAR(x.i.d, want, 1e-9 * want) << "gain " << gain;
    EXPECT_NEAR(x.i.q, 0.0, 1e-12);
  }
}

// Back-EMF: rotating at w with constant flux, holding i needs u = R i + j w psi.
TEST(Plant, RotatingFrameDerivativeIsZeroAtSteadyState) {
  LinearWinding w(2e-4);
  PlantModel m = LinearPlant(w, 0.01);
  const double we = 400, id = -5, iq = 20;
  State x{2e-4 * id, 2e-4 * iq, id, iq, Vec2{id, iq}};
  const double ud = 0.01 * id - we * 2e-4 * iq, uq = 0.01 * iq + we * 2e-4 * id;
  // Command in alpha-beta at theta = 0.3.
  double ual, ube;
  InversePark(ud, uq, 0.3, &ual, &ube);
  double dd, dq, dl1, dl2;
  Vec2 i;
  Derivative(m, x, 0.3, we, ual, ube, &dd, &dq, &dl1, &dl2, &i);
  EXPECT_NEAR(dd, 0.0, 1e-12);
  EXPECT_NEAR(dq, 0.0, 1e-12);
}

// Dead time at large currents (ia > 0, ib, ic < 0): the per-phase errors
// -k, +k, +k (k = Td/Ts Udc) give alpha = -4k/3, beta = 0.
TEST(Plant, DeadTimeErrorAtLargeCurrents) {
  PlantModel m;
  m.dead_time_s = 2e-6;
  m.ts_s = 1e-4;
  m.udc_v = 50;
  double ua, ub;
  DeadTimeError(m, 50, -25, -25, &ua, &ub);
  const double k = 2e-6 / 1e-4 * 50;
  EXPECT_NEAR(ua, -4 * k / 3, 1e-9);
  EXPECT_NEAR(ub, 0.0, 1e-9);
}

// A switch threshold adds V_th to each phase's error, independent of Udc:
// at large currents alpha = -4 (k + V_th) / 3; halving Udc halves only k.
TEST(Plant, ThresholdVoltageDoesNotScaleWithUdc) {
  PlantModel m;
  m.dead_time_s = 2e-6;
  m.threshold_v = 0.8;
  m.ts_s = 1e-4;
  for (double udc : {50.0, 25.0}) {
    m.udc_v = udc;
    double ua, ub;
    DeadTimeError(m, 50, -25, -25, &ua, &ub);
    const double k = 2e-6 / 1e-4 * udc;
    EXPECT_NEAR(ua, -4 * (k + 0.8) / 3, 1e-9) << udc;
    EXPECT_NEAR(ub, 0.0, 1e-9);
  }
  // The slope is a series resistance in every phase: at steady state
  // u = (Rs + r_on) i holds the current (derivative zero).
  PlantModel r;
  ToArray(SaturationParams{}, r.p);
  r.rs_ohm = 0.01;
  r.r_hf_ohm = 0;
  r.slope_ohm = 0.004;
  double pd, pq;
  r.Flux(30, 40, 0.0, &pd, &pq);
  State x{pd, pq, 30, 40, Vec2{30, 40}};
  double dd, dq, dl1, dl2;
  Vec2 i;
  Derivative(r, x, 0.0, 0.0, 0.014 * 30, 0.014 * 40, &dd, &dq, &dl1, &dl2, &i);
  EXPECT_NEAR(dd, 0.0, 1e-9);
  EXPECT_NEAR(dq, 0.0, 1e-9);
}

// Iron loss at steady state at speed: with u = Rs (i_m + g e) + e and
// e = w J psi(i_m) the flux does not move, and the terminal current is the
// magnetising one plus g e.
TEST(Plant, IronLossCurrentAtSteadyState) {
  PlantModel m;
  ToArray(SaturationParams{}, m.p);
  m.rs_ohm = 0.01;
  m.r_hf_ohm = 0;
  m.g_fe_s = 1.0 / 20;
  const double we = 800, idm = -30, iqm = 40;
  double pd, pq;
  m.Flux(idm, iqm, 0.0, &pd, &pq);
  State x{pd, pq, idm, iqm, Vec2{idm, iqm}};
  const double ed = -we * pq, eq = we * pd;
  const double ud = m.rs_ohm * (idm + m.g_fe_s * ed) + ed, uq = m.rs_ohm * (iqm + m.g_fe_s * eq) + eq;
  double dd, dq, dl1, dl2;
  Vec2 i, it;
  Derivative(m, x, 0.0, we, ud, uq, &dd, &dq, &dl1, &dl2, &i, &it);
  EXPECT_NEAR(dd, 0.0, 1e-9);
  EXPECT_NEAR(dq, 0.0, 1e-9);
  EXPECT_NEAR(it.d, idm + ed / 20, 1e-9);
  EXPECT_NEAR(it.q, iqm + eq / 20, 1e-9);
  EXPECT_GT(std::abs(ed / 20), 0.1);   // the loss current is not negligible here
}

// A page of the project's docs, whole ("" when missing: the checks fail).
std::string Doc(const std::string& name) {
  std::ifstream f(std::string(FLUXCAL_SOURCE_DIR) + "/docs/" + name);
  std::stringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

TEST(Catalogue, RowsAreUniqueAndDocumented) {
  const std::string doc = Doc("diagnosis-report.md");
  std::set<std::string> names, params;
  for (const auto& row : EffectCatalogue()) {
    EXPECT_TRUE(names.insert(std::string(row.name)).second) << row.name;
    EXPECT_NE(doc.find("`" + std::string(row.name) + "`"), std::string::npos) << row.name << " not in the report doc";
    EXPECT_FALSE(row.explanation.empty()) << row.name;
    for (const auto& p : row.parameters) {
      EXPECT_TRUE(params.insert(std::string(p.name)).second) << p.name << " used by two effects";
      EXPECT_GT(p.fit_scale, 0.0) << p.name;
      EXPECT_NE(doc.find("`" + std::string(p.name) + "`"), std::string::npos) << p.name << " not documented";
    }
  }
  EXPECT_EQ(&EffectParam("dead_time", "dead_time_s"), &FindEffect("dead_time")->parameters[0]);
  // The registry (simulation/catalogue/): one entry per row, in the rows'
  // order; each --effects key owned once (bench effects included) and
  // switching its effect on away from the neutral value.
  ASSERT_EQ(CatalogueEffects().size(), EffectCatalogue().size());
  std::set<std::string> keys;
  for (const auto& x : BenchEffectParameterNames()) keys.insert(x);
  for (size_t k = 0; k < CatalogueEffects().size(); ++k) {
    const auto& c = CatalogueEffects()[k];
    EXPECT_EQ(c.row.name, EffectCatalogue()[k].name);
    ASSERT_NE(c.truth, nullptr) << c.row.name;
    for (const auto& key : c.keys) {
      EXPECT_TRUE(keys.insert(std::string(key.name)).second) << key.name << " owned twice";
      EXPECT_EQ((key.value != nullptr) + (key.optional != nullptr) + (key.integer != nullptr), 1) << key.name;
    }
    if (c.keys.empty()) continue;
    // Every key of the effect at 2 (a real order, gains of 2, ...) turns it on.
    std::string spec;
    for (const auto& key : c.keys) spec += std::string(spec.empty() ? "" : ",") + std::string(key.name) + "=2";
    Effects e;
    ASSERT_TRUE(ParseEffects(spec, &e, nullptr).ok()) << spec;
    const auto on = ActiveEffectNames(e);
    EXPECT_NE(std::find(on.begin(), on.end(), std::string(c.row.name)), on.end()) << spec;
    EXPECT_FALSE(c.truth(e).empty()) << c.row.name;
  }
  EXPECT_EQ(FindEffect("no_such_effect"), nullptr);
}

// The registry's sensor hooks compose as the bench reads: gain, then
// offset, per phase; the angle error sums offset and harmonic; the torque
// transducer loses friction and drag.
TEST(Catalogue, SensorHooksComposeAsTheBenchReads) {
  Effects e;
  ASSERT_TRUE(ParseEffects("gain_a=1.02,gain_c=0.99,offset_b_a=0.3,offset_c_a=-0.1,offset_rad=0.02,"
                           "harmonic_amplitude_rad=0.01,harmonic_phase_rad=0.5,friction_nm=0.2,"
                           "viscous_nm_per_rad_s=0.001",
                           &e, nullptr)
                  .ok());
  double ia = 10, ib = -4, ic = -6;
  SenseCurrents(e, &ia, &ib, &ic);
  EXPECT_DOUBLE_EQ(ia, 10.2);
  EXPECT_DOUBLE_EQ(ib, -3.7);
  EXPECT_DOUBLE_EQ(ic, 0.99 * -6 - 0.1);
  EXPECT_DOUBLE_EQ(AngleSensorError(e, 0.7), 0.02 + 0.01 * std::sin(1.4 + 0.5));
  const double w_m = 1500 * 2 * kPi / 60;
  EXPECT_NEAR(TorqueReadingLoss(e, 1500), 0.2 + 0.001 * w_m, 1e-12);
  EXPECT_NEAR(TorqueReadingLoss(e, -1500), -(0.2 + 0.001 * w_m), 1e-12);
  PlantModel m;
  ApplyEffectsToPlant(Effects{}, &m);
  EXPECT_EQ(m.voltage_gain, 1.0);
  EXPECT_EQ(m.g_fe_s, 0.0);
  EXPECT_EQ(m.r_hf_ohm, 0.0);
}

// The twin-only effects (simulation/bench_effect.h): each named with its
// parameters in docs/simulation.md's table, parameter names unique across
// them and the catalogue (one --effects key, one owner), off by default.
TEST(BenchEffects, RegistryIsDocumented) {
  const std::string doc = Doc("simulation.md");
  std::set<std::string> names, params;
  for (const auto& row : EffectCatalogue()) {
    for (const auto& p : row.parameters) params.insert(std::string(p.name));
  }
  const auto all = AllBenchEffects();
  EXPECT_GE(all.size(), 7u);
  for (const auto& e : all) {
    const std::string name(e->Name());
    EXPECT_TRUE(names.insert(name).second) << name;
    EXPECT_NE(doc.find("`" + name + "`"), std::string::npos) << name << " not in docs/simulation.md";
    EXPECT_FALSE(e->Meaning().empty()) << name;
    EXPECT_FALSE(e->Active()) << name << " on by default";
    for (const auto& p : e->Parameters()) {
      const std::string key(p.name);
      EXPECT_TRUE(params.insert(key).second) << key << " used twice";
      EXPECT_NE(doc.find("`" + key + "`"), std::string::npos) << key << " not in docs/simulation.md";
    }
  }
}

TEST(Catalogue, ParseEffectsAndActiveNames) {
  Effects e;
  double noise = 0.05;
  ASSERT_TRUE(ParseEffects("offset_b_a=0.8,udc_sense_gain=0.954,noise_a=0.1", &e, &noise).ok());
  EXPECT_EQ(e.offset_b_a, 0.8);
  EXPECT_EQ(e.udc_sense_gain, 0.954);
  EXPECT_EQ(noise, 0.1);
  EXPECT_EQ(ActiveEffectNames(e), (std::vector<std::string>{"current_sensor_offset", "dc_link_sense_gain"}));
  EXPECT_EQ(EffectParameters(e, "current_sensor_offset").at("offset_b_a"), 0.8);
  EXPECT_TRUE(ActiveEffectNames(Effects{}).empty());
  const auto bad = ParseEffects("udc_gain=1", &e, &noise);
  EXPECT_FALSE(bad.ok());
  EXPECT_NE(bad.message().find("udc_sense_gain"), std::string::npos) << "lists the known keys";
}

}  // namespace
}  // namespace fluxcal::sim
