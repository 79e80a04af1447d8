// Diagnosis on concealed effects: a test matrix built with the twin (each
// effect alone with random realistic parameters, pairs, clean sets), the
// independent example sets, and the paper's Table 1.
#include "diagnosis/diagnose.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <functional>
#include <random>
#include <set>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "physics/torque.h"
#include "identification/identify.h"
#include "io/flux_map.h"
#include "fitting/fit.h"
#include "simulation/twin.h"
#include "tables/tables.h"
#include "tests/support/shared_examples.h"
#include "tinyxml2.h"

namespace fluxcal::diag {
namespace {

namespace fs = std::filesystem;

std::set<std::string> Named(const DiagnosisReport& r) {
  std::set<std::string> s;
  for (const auto& f : r.findings) s.insert(f.effect);
  return s;
}

// What is left unexplained, for failure messages: each remaining mismatch's
// signal, kind, order, size, significance and where.
std::string Remaining(const DiagnosisReport& r) {
  std::string s;
  for (const auto& m : r.remaining) {
    s += absl::StrFormat("\n  remaining %s %s order %d %.4g Hz size %.3g A %.1f sigma at %s", m.signal, m.kind,
                         m.order, m.frequency_hz, m.size_a, m.significance_sigma, m.where);
  }
  for (const auto& h : r.held_out) {
    if (!h.passed) {
      s += absl::StrFormat("\n  held-out %s failed: %.1f sigma, residual %.3g", h.signal, h.significance_sigma,
                           h.residual_rms);
    }
  }
  return s;
}

const Finding* Find(const DiagnosisReport& r, const std::string& effect) {
  for (const auto& f : r.findings) if (f.effect == effect) return &f;
  return nullptr;
}

DiagnosisReport SimulateAndDiagnose(const sim::TwinConfig& cfg) {
  sim::Plan plan = sim::DefaultPlan();
  plan.record_s = 0.1;    // the default 50 injection periods
  auto sim = sim::Simulate(cfg, plan);
  EXPECT_TRUE(sim.ok());
  auto rep = Diagnose(sim->set);
  EXPECT_TRUE(rep.ok()) << rep.status();
  return *rep;
}

// A matrix case's bench: the twin's motor on the default plan, or the
// second motor (data/motors/second_motor.json) on the EOL-like plan
// (data/plans/eol_like_plan.json), with production spread from `seed`.
struct CaseBench {
  sim::TwinConfig cfg;
  sim::Plan plan;
  bool ok = true;
};
CaseBench MotorOnPlan(bool second_motor, uint64_t seed) {
  CaseBench b;
  b.plan = sim::DefaultPlan();
  if (second_motor) {
    const fs::path data = fs::path(FLUXCAL_SOURCE_DIR) / "data";
    auto eol = sim::LoadPlanJson((data / "plans" / "eol_like_plan.json").string());
    b.ok = eol.ok() && sim::LoadMotorJson((data / "motors" / "second_motor.json").string(), &b.cfg).ok();
    if (eol.ok()) b.plan = *eol;
  }
  b.cfg.seed = seed;
  b.cfg.motor = sim::PerturbForProduction(b.cfg.motor, seed);
  return b;
}

// A recording of `cfg` on `plan`, diagnosed with the default options.
absl::StatusOr<DiagnosisReport> SimulateThenDiagnose(const sim::TwinConfig& cfg, const sim::Plan& plan) {
  auto simulated = sim::Simulate(cfg, plan);
  if (!simulated.ok()) return simulated.status();
  return Diagnose(simulated->set);
}

TEST(Matrix, CleanSetsHaveNoFindings) {
  for (uint64_t seed : {1u, 2u, 3u}) {
    sim::TwinConfig cfg;
    cfg.seed = seed;
    cfg.motor = sim::PerturbForProduction(cfg.motor, seed);
    const auto r = SimulateAndDiagnose(cfg);
    EXPECT_EQ(r.verdict, "no_mismatch") << "seed " << seed;
    EXPECT_TRUE(r.findings.empty()) << "seed " << seed << ": " << r.findings[0].effect;
  }
}

// A quiet sensor on a coarse ADC: 0.02 A of noise before a 0.122 A step
// (12 bits over +-250 A) does not dither the quantiser, whose error then
// follows the signal and puts ~10 mA lines at 6-10 x the injection into
// every phase and the zero sequence, 12-15 sigma over the white floor of
// a 50-period record. That is the sensor's resolution, not physics the
// model lacks: the clean set is `no_mismatch` (it was `unexplained`), and
// a 2 % sensor gain on the same bench is found and `explained` (it was
// `partly_explained` with the quantiser's lines left over).
// (waveform.cc, QuantisationLineA; docs/diagnosis.md.)
TEST(Matrix, CoarseAdcQuietSensor) {
  sim::TwinConfig cfg;
  cfg.seed = 36;
  cfg.motor = sim::PerturbForProduction(cfg.motor, cfg.seed);
  cfg.sensors.noise_a = 0.02;
  const auto clean = SimulateAndDiagnose(cfg);
  EXPECT_EQ(clean.verdict, "no_mismatch") << Remaining(clean);
  EXPECT_TRUE(clean.findings.empty());
  cfg.effects.gain_a = 1.02;
  const auto gain = SimulateAndDiagnose(cfg);
  EXPECT_EQ(gain.verdict, "explained") << Remaining(gain);
  EXPECT_EQ(Named(gain), std::set<std::string>{"current_sensor_gain"});
  const Finding* g = Find(gain, "current_sensor_gain");
  ASSERT_NE(g, nullptr);
  // Phase a's gain against phase b's (a common gain is absorbed in the
  // magnetics and the resistance where the observables cannot part them).
  EXPECT_NEAR(g->parameters.at("gain_a") - g->parameters.at("gain_b"), 0.02, 0.003);
}

// Each effect alone, random realistic parameter, random seed.
TEST(Matrix, EachEffectAlone) {
  std::mt19937_64 rng(2026);
  std::uniform_real_distribution<double> u(0, 1);
  auto sign = [&] { return u(rng) < 0.5 ? -1.0 : 1.0; };
  for (int trial = 0; trial < 9; ++trial) {
    sim::TwinConfig cfg;
    cfg.seed = 100 + trial;
    std::string effect;
    auto& e = cfg.effects;
    switch (trial) {
      case 0: effect = "dead_time"; e.dead_time_s = 1e-6 + 2e-6 * u(rng); break;
      case 1: effect = "cross_saturation"; e.cross_saturation = 2e-5 + 2e-5 * u(rng); break;
      case 2: effect = "stator_resistance"; e.rs_ohm = cfg.motor.rs_ohm * (1 + sign() * (0.15 + 0.2 * u(rng))); break;
      case 3: effect = "hf_resistance"; e.r_hf_ohm = 0.02 + 0.03 * u(rng); break;
      case 4: effect = "position_offset"; e.offset_rad = sign() * (0.03 + 0.05 * u(rng)); break;
      case 5: effect = "magnet_temperature"; e.psi_pm_wb = cfg.motor.sat.psi_pm_wb * (1 - 0.05 - 0.05 * u(rng)); break;
      case 6: effect = "sampling_delay"; e.delay_s = 20e-6 + 20e-6 * std::floor(2 * u(rng)); break;
      case 7: effect = "current_sensor_gain"; e.gain_a = 1 + sign() * 0.02; e.gain_b = 1 - 0.015; break;
      case 8: effect = "spatial_harmonics"; e.order = u(rng) < 0.5 ? 6 : 4; e.amplitude_h = 4e-6 + 4e-6 * u(rng); break;
    }
    const auto r = SimulateAndDiagnose(cfg);
    if (effect == "cross_saturation") {
      // The machine's own magnetics: the baseline is the set's calibration,
      // which carries cross saturation, so it is never missing physics
      // (docs/diagnosis.md, "The baseline").
      EXPECT_EQ(r.verdict, "no_mismatch") << effect;
      EXPECT_TRUE(r.findings.empty()) << effect;
      continue;
    }
    const Finding* f = Find(r, effect);
    ASSERT_NE(f, nullptr) << effect << ": not named; verdict " << r.verdict;
    EXPECT_NE(r.verdict, "unexplained") << effect;
    EXPECT_EQ(r.findings[0].effect, effect) << "the concealed effect is accepted first";
    // Tolerances of the issue: dead time 20 %, offset 0.5 electrical
    // degrees, sensor gains 0.5 %, resistances 15 %.
    if (effect == "dead_time") {
      EXPECT_NEAR(f->parameters.at("dead_time_s") / e.dead_time_s, 1.0, 0.2);
    }
    if (effect == "stator_resistance") {
      EXPECT_NEAR(f->parameters.at("rs_ohm") / *e.rs_ohm, 1.0, 0.15);
    }
    if (effect == "hf_resistance") {
      EXPECT_NEAR(f->parameters.at("r_hf_ohm") / e.r_hf_ohm, 1.0, 0.15);
    }
    if (effect == "position_offset") {
      EXPECT_NEAR(f->parameters.at("offset_rad"), e.offset_rad, 0.5 * M_PI / 180);
    }
    if (effect == "magnet_temperature") {
      EXPECT_NEAR(f->parameters.at("psi_pm_wb") / *e.psi_pm_wb, 1.0, 0.01);
    }
    if (effect == "sampling_delay") {
      EXPECT_NEAR(f->parameters.at("delay_s") / e.delay_s, 1.0, 0.2);
    }
    if (effect == "spatial_harmonics") {
      EXPECT_EQ(f->parameters.at("order"), e.order);
      EXPECT_NEAR(f->parameters.at("amplitude_h") / e.amplitude_h, 1.0, 0.2);
    }
    if (effect == "current_sensor_gain") {
      EXPECT_NEAR(f->parameters.at("gain_a"), e.gain_a, 0.005);
      EXPECT_NEAR(f->parameters.at("gain_b"), e.gain_b, 0.005);
      EXPECT_NEAR(f->parameters.at("gain_c"), e.gain_c, 0.005);
    }
    // At least 3x lower residual, or down to the noise: the baseline is the
    // set's own flexible calibration, which takes up part of an effect that
    // looks like magnetics (a spatial harmonic), so the ratio is smaller
    // where the start was already closer; then the final residual is that
    // of the same motor and seed recorded clean (within 25 %).
    const double ratio = r.baseline.residual_rms / r.final_model.residual_rms;
    if (ratio < 3.0) {
      sim::TwinConfig clean;
      clean.seed = cfg.seed;
      const auto rc = SimulateAndDiagnose(clean);
      EXPECT_LE(r.final_model.residual_rms, 1.25 * rc.baseline.residual_rms)
          << effect << ": residual " << r.baseline.residual_rms << " -> " << r.final_model.residual_rms
          << ", clean recording of the same motor " << rc.baseline.residual_rms;
    }
  }
}

TEST(Matrix, PairsOfEffects) {
  {
    sim::TwinConfig cfg;
    cfg.seed = 301;
    cfg.effects.dead_time_s = 1.5e-6;
    cfg.effects.offset_rad = 0.05;
    const auto r = SimulateAndDiagnose(cfg);
    EXPECT_TRUE(Named(r).count("dead_time") && Named(r).count("position_offset")) << r.verdict;
  }
  {
    sim::TwinConfig cfg;
    cfg.seed = 302;
    cfg.effects.rs_ohm = 0.014;
    cfg.effects.psi_pm_wb = 0.0106;
    const auto r = SimulateAndDiagnose(cfg);
    EXPECT_TRUE(Named(r).count("stator_resistance") && Named(r).count("magnet_temperature")) << r.verdict;
  }
}

// Pairs that share a signature, separated by what distinguishes them: an
// HF resistance and a delay both turn the HF phasor (the delay also rotates
// the steady-state voltages in proportion to speed); psi_pm and an angle
// offset both move the steady-state voltages (the offset also rotates the
// negative sequence). Before the stepwise selection's backward round, a
// constant offset stood in for the delay at mid speed (delay 5 us of 30,
// an offset of 1.1 degrees that is not there).
TEST(Matrix, PairsSharingASignature) {
  {
    sim::TwinConfig cfg;
    cfg.seed = 9;
    cfg.motor = sim::PerturbForProduction(cfg.motor, cfg.seed);
    cfg.effects.r_hf_ohm = 0.05;
    cfg.effects.delay_s = 30e-6;
    const auto r = SimulateAndDiagnose(cfg);
    EXPECT_EQ(Named(r), (std::set<std::string>{"hf_resistance", "sampling_delay"})) << r.verdict;
    if (const Finding* f = Find(r, "hf_resistance")) {
      EXPECT_NEAR(f->parameters.at("r_hf_ohm") / 0.05, 1.0, 0.15);
    }
    if (const Finding* f = Find(r, "sampling_delay")) {
      EXPECT_NEAR(f->parameters.at("delay_s") / 30e-6, 1.0, 0.15);
    }
    EXPECT_EQ(r.verdict, "explained");
  }
  {
    sim::TwinConfig cfg;
    cfg.seed = 9;
    cfg.motor = sim::PerturbForProduction(cfg.motor, cfg.seed);
    cfg.effects.psi_pm_wb = 0.0108;
    cfg.effects.offset_rad = 0.04;
    const auto r = SimulateAndDiagnose(cfg);
    EXPECT_EQ(Named(r), (std::set<std::string>{"magnet_temperature", "position_offset"})) << r.verdict;
    if (const Finding* f = Find(r, "magnet_temperature")) {
      EXPECT_NEAR(f->parameters.at("psi_pm_wb") / 0.0108, 1.0, 0.02);
    }
    if (const Finding* f = Find(r, "position_offset")) {
      EXPECT_NEAR(f->parameters.at("offset_rad"), 0.04, 0.5 * M_PI / 180);
    }
    EXPECT_EQ(r.verdict, "explained");
  }
}

// A second motor (data/motors/second_motor.json: other inductances, Rs and
// psi_pm, a slower controller, more noise) with production spread, on a
// plan shaped like an EOL run (data/plans/eol_like_plan.json: 36 locked
// points at scattered rotor angles, 6 rotating points 200-2000 rpm, 20
// steady-state rows with torque). Each case once went wrong:
//  - order-4 harmonics: at 1500 rpm (5 w_e = w_i) the harmonic's
//    fundamental-current voltage lands on the injection frequency;
//  - a half-sample delay: modelled as a pure phase it biased the
//    inductances by 1 % and a spurious magnet_temperature followed;
//  - a 2 % sensor gain and a 5 mOhm HF resistance: missed when noisy torque
//    rows near zero torque dominated the relative residual.
TEST(Matrix, SecondMotorEolLikePlan) {
  const fs::path data = fs::path(FLUXCAL_SOURCE_DIR) / "data";
  auto plan = sim::LoadPlanJson((data / "plans" / "eol_like_plan.json").string());
  ASSERT_TRUE(plan.ok()) << plan.status();
  struct Case {
    std::string effect;
    uint64_t seed;
    std::function<void(sim::Effects*)> set;
  };
  const std::vector<Case> cases = {
      {"", 11, [](sim::Effects*) {}},
      {"spatial_harmonics", 25, [](sim::Effects* e) { e->order = 4; e->amplitude_h = 1.2e-5; }},
      {"sampling_delay", 23, [](sim::Effects* e) { e->delay_s = 50e-6; }},
      {"current_sensor_gain", 36, [](sim::Effects* e) { e->gain_a = 1.02; }},
      {"hf_resistance", 21, [](sim::Effects* e) { e->r_hf_ohm = 0.005; }},
  };
  for (const auto& c : cases) {
    sim::TwinConfig cfg;
    ASSERT_TRUE(sim::LoadMotorJson((data / "motors" / "second_motor.json").string(), &cfg).ok());
    cfg.seed = c.seed;
    cfg.motor = sim::PerturbForProduction(cfg.motor, c.seed);
    c.set(&cfg.effects);
    auto simulated = sim::Simulate(cfg, *plan);
    ASSERT_TRUE(simulated.ok()) << simulated.status();
    auto r = Diagnose(simulated->set);
    ASSERT_TRUE(r.ok()) << r.status();
    const std::string label = c.effect.empty() ? "clean" : c.effect;
    if (c.effect.empty()) {
      EXPECT_EQ(r->verdict, "no_mismatch") << label;
      EXPECT_TRUE(r->findings.empty()) << label << ": " << r->findings[0].effect;
      continue;
    }
    EXPECT_EQ(r->verdict, "explained") << label;
    ASSERT_EQ(r->findings.size(), 1u) << label << ": named " << r->findings.size() << " effects, first "
                                      << (r->findings.empty() ? "-" : r->findings[0].effect);
    const Finding& f = r->findings[0];
    EXPECT_EQ(f.effect, c.effect);
    const auto& e = cfg.effects;
    if (c.effect == "spatial_harmonics") {
      EXPECT_EQ(f.parameters.at("order"), 4);
      EXPECT_NEAR(f.parameters.at("amplitude_h") / e.amplitude_h, 1.0, 0.2);
    } else if (c.effect == "sampling_delay") {
      EXPECT_NEAR(f.parameters.at("delay_s") / e.delay_s, 1.0, 0.02);
    } else if (c.effect == "current_sensor_gain") {
      EXPECT_NEAR(f.parameters.at("gain_a"), e.gain_a, 0.005);
      EXPECT_NEAR(f.parameters.at("gain_b"), 1.0, 0.005);
      EXPECT_NEAR(f.parameters.at("gain_c"), 1.0, 0.005);
    } else if (c.effect == "hf_resistance") {
      EXPECT_NEAR(f.parameters.at("r_hf_ohm") / e.r_hf_ohm, 1.0, 0.15);
    }
  }
}

// The catalogue's extensions (docs/diagnosis-report.md) concealed alone, on
// the twin's motor (default plan) and the second motor (EOL-like plan):
// named, alone, `explained`, parameters within 15 %. (Three seeds each and
// pairs: scripts/diagnosis-probe.py.)
TEST(Matrix, ExtensionsAloneOnBothMotors) {
  struct Case {
    std::string effect;
    bool second_motor;
    uint64_t seed;
    std::function<void(sim::Effects*)> set;
  };
  const std::vector<Case> cases = {
      {"dc_link_sense_gain", false, 61, [](sim::Effects* e) { e->udc_sense_gain = 0.954; }},
      {"dc_link_sense_gain", true, 62, [](sim::Effects* e) { e->udc_sense_gain = 1.03; }},
      {"current_sensor_offset", false, 63, [](sim::Effects* e) { e->offset_b_a = 1.0; }},
      {"current_sensor_offset", true, 64, [](sim::Effects* e) { e->offset_a_a = 0.8; e->offset_c_a = -0.6; }},
      {"phase_resistance_imbalance", false, 65, [](sim::Effects* e) { e->dr_a_ohm = 0.003; }},
      {"phase_resistance_imbalance", true, 66, [](sim::Effects* e) { e->dr_b_ohm = 0.003; }},
      {"stator_temperature_drift", false, 67, [](sim::Effects* e) { e->winding_temp_rise_k = 20; }},
      {"stator_temperature_drift", true, 68, [](sim::Effects* e) { e->winding_temp_rise_k = 15; }},
  };
  for (const auto& c : cases) {
    auto [cfg, plan, bench_ok] = MotorOnPlan(c.second_motor, c.seed);
    ASSERT_TRUE(bench_ok);
    c.set(&cfg.effects);
    auto r = SimulateThenDiagnose(cfg, plan);
    ASSERT_TRUE(r.ok()) << r.status();
    const std::string label = c.effect + (c.second_motor ? " (second motor)" : "");
    EXPECT_EQ(r->verdict, "explained") << label << Remaining(*r);
    const auto& e = cfg.effects;
    // A bad joint adds resistance: its common part (mean of the three) is a
    // real stator_resistance change, named beside it when material.
    const double dr_mean = (e.dr_a_ohm + e.dr_b_ohm + e.dr_c_ohm) / 3;
    std::set<std::string> want = {c.effect};
    if (dr_mean > 0.03 * cfg.motor.rs_ohm) want.insert("stator_resistance");
    ASSERT_EQ(Named(*r), want) << label << ": first " << (r->findings.empty() ? "-" : r->findings[0].effect);
    const Finding& f = *Find(*r, c.effect);
    if (const Finding* rs = Find(*r, "stator_resistance")) {
      EXPECT_NEAR(rs->parameters.at("rs_ohm") / (cfg.motor.rs_ohm + dr_mean), 1.0, 0.15) << label;
    }
    if (c.effect == "stator_temperature_drift") {
      EXPECT_NEAR(f.parameters.at("winding_temp_rise_k") / e.winding_temp_rise_k, 1.0, 0.15) << label;
    } else if (c.effect == "phase_resistance_imbalance") {
      const double want_dr[3] = {e.dr_a_ohm - dr_mean, e.dr_b_ohm - dr_mean, e.dr_c_ohm - dr_mean};
      const char* names[3] = {"dr_a_ohm", "dr_b_ohm", "dr_c_ohm"};
      const double size = std::max({std::abs(want_dr[0]), std::abs(want_dr[1]), std::abs(want_dr[2])});
      for (int x = 0; x < 3; ++x) EXPECT_NEAR(f.parameters.at(names[x]), want_dr[x], 0.15 * size) << label << names[x];
    } else if (c.effect == "dc_link_sense_gain") {
      EXPECT_NEAR((f.parameters.at("udc_sense_gain") - 1) / (e.udc_sense_gain - 1), 1.0, 0.15) << label;
    } else {
      // The zero-sum set of the truth (the common part is unobservable).
      const double mean = (e.offset_a_a + e.offset_b_a + e.offset_c_a) / 3;
      const double want[3] = {e.offset_a_a - mean, e.offset_b_a - mean, e.offset_c_a - mean};
      const char* names[3] = {"offset_a_a", "offset_b_a", "offset_c_a"};
      const double size = std::max({std::abs(want[0]), std::abs(want[1]), std::abs(want[2])});
      for (int x = 0; x < 3; ++x) EXPECT_NEAR(f.parameters.at(names[x]), want[x], 0.15 * size) << label << names[x];
    }
    for (const auto& h : r->held_out) EXPECT_TRUE(h.passed) << label << ": " << h.signal;
  }
}

// Physics outside the vocabulary (a catalogue row removed, its effect
// concealed) is never `explained`. A DC-link voltage read 4.6 % low without
// its row is fitted by stator_resistance + magnet_temperature +
// current_sensor_gain all at one ratio; refitted without the torque rows,
// that model mispredicts them, so the verdict is partial and says why.
// The inverter's soft-sign current is the inverter's, not the model's
// 1 A: concealed dead times with i_th of 0.5, 2 and 3 A on both motors are
// named with Td and i_th within 15 % (diagnose.cc profiles it).
TEST(Matrix, DeadTimeSoftSignCurrent) {
  struct Case { bool second; uint64_t seed; double td_s, ith_a; };
  for (const Case& c : {Case{false, 71, 2.0e-6, 0.5}, Case{false, 72, 1.5e-6, 3.0}, Case{true, 73, 2.5e-6, 2.0}}) {
    CaseBench b = MotorOnPlan(c.second, c.seed);
    ASSERT_TRUE(b.ok);
    b.cfg.effects.dead_time_s = c.td_s;
    b.cfg.effects.dead_time_i_th_a = c.ith_a;
    auto r = SimulateThenDiagnose(b.cfg, b.plan);
    ASSERT_TRUE(r.ok()) << r.status();
    const Finding* f = Find(*r, "dead_time");
    ASSERT_NE(f, nullptr) << "i_th " << c.ith_a << ": dead time not named; verdict " << r->verdict;
    std::printf("dead time %.2g s, i_th %.2g A (%s motor): found %.4g s, i_th %.4g A\n", c.td_s, c.ith_a,
                c.second ? "second" : "twin", f->parameters.at("dead_time_s"),
                f->parameters.count("i_th_a") ? f->parameters.at("i_th_a") : -1.0);
    EXPECT_NEAR(f->parameters.at("dead_time_s") / c.td_s, 1.0, 0.15);
    ASSERT_TRUE(f->parameters.count("i_th_a")) << "i_th not estimated at " << c.ith_a << " A";
    EXPECT_NEAR(f->parameters.at("i_th_a") / c.ith_a, 1.0, 0.15);
    EXPECT_EQ(r->verdict, "explained");
  }
}

TEST(Honesty, OutsideTheCatalogueIsNeverExplained) {
  struct Case {
    std::string effect;
    std::function<void(sim::Effects*)> set;
  };
  const std::vector<Case> cases = {
      {"dc_link_sense_gain", [](sim::Effects* e) { e->udc_sense_gain = 0.954; }},
      {"current_sensor_offset", [](sim::Effects* e) { e->offset_b_a = 1.5; }},
  };
  for (const auto& c : cases) {
    sim::TwinConfig cfg;
    cfg.seed = 71;
    cfg.motor = sim::PerturbForProduction(cfg.motor, cfg.seed);
    c.set(&cfg.effects);
    auto simulated = sim::Simulate(cfg, sim::DefaultPlan());
    ASSERT_TRUE(simulated.ok());
    DiagnoseOptions opt;
    opt.excluded_effects = {c.effect};
    auto r = Diagnose(simulated->set, opt);
    ASSERT_TRUE(r.ok());
    EXPECT_NE(r->verdict, "explained") << c.effect;
    EXPECT_NE(r->verdict, "no_mismatch") << c.effect;
    EXPECT_FALSE(r->mismatches.empty()) << c.effect << ": located";
    if (r->verdict == "unexplained") {
      EXPECT_FALSE(r->rejected.empty()) << c.effect << ": says what it tried";
    }
  }
}

// inverter_voltage_drop (docs/diagnosis.md). With held points at a second
// DC-link voltage (sim::WithSecondUdc) the switches' threshold is told from
// the dead time, alone and beside it, on both motors, three seeds each;
// its slope is in series with Rs and is named as stator_resistance's
// alternative; at one Udc a threshold is named as the dead time it equals,
// with the threshold as the alternative.
TEST(Matrix, InverterVoltageDrop) {
  struct Case {
    bool second_motor, second_udc;
    uint64_t seed;
    double threshold_v, slope_ohm, dead_time_s;
  };
  const std::vector<Case> cases = {
      {false, true, 81, 0.8, 0, 0},      {false, true, 82, 0.5, 0, 0},    {false, true, 83, 1.1, 0, 0},
      {true, true, 84, 0.8, 0, 0},       {true, true, 85, 0.6, 0, 0},     {true, true, 86, 1.0, 0, 0},
      {false, true, 87, 0.7, 0, 1e-6},   {true, true, 88, 0.6, 0, 1.2e-6}, {false, true, 89, 0.9, 0, 0.8e-6},
      {false, true, 90, 0.9, 0.004, 0},  {true, true, 91, 0, 0.003, 0},
      {false, false, 92, 0.8, 0, 0},     {true, false, 93, 0.6, 0, 0},
  };
  for (const auto& c : cases) {
    auto [cfg, plan, bench_ok] = MotorOnPlan(c.second_motor, c.seed);
    ASSERT_TRUE(bench_ok);
    if (c.second_udc) plan = sim::WithSecondUdc(plan, 0.7 * cfg.drive.udc_v);
    cfg.effects.threshold_v = c.threshold_v;
    cfg.effects.slope_ohm = c.slope_ohm;
    cfg.effects.dead_time_s = c.dead_time_s;
    auto r = SimulateThenDiagnose(cfg, plan);
    ASSERT_TRUE(r.ok()) << r.status();
    const std::string label = absl::StrCat("seed ", c.seed);
    EXPECT_EQ(r->verdict, "explained") << label << Remaining(*r);
    std::set<std::string> want;
    if (c.threshold_v > 0) want.insert(c.second_udc ? "inverter_voltage_drop" : "dead_time");
    if (c.dead_time_s > 0) want.insert("dead_time");
    if (c.slope_ohm > 0) want.insert("stator_resistance");
    ASSERT_EQ(Named(*r), want) << label;
    if (c.threshold_v > 0 && c.second_udc) {
      EXPECT_NEAR(Find(*r, "inverter_voltage_drop")->parameters.at("threshold_v") / c.threshold_v, 1.0, 0.15)
          << label;
    }
    if (c.dead_time_s > 0) {
      EXPECT_NEAR(Find(*r, "dead_time")->parameters.at("dead_time_s") / c.dead_time_s, 1.0, 0.15) << label;
    }
    if (!c.second_udc) {
      const Finding& f = *Find(*r, "dead_time");
      ASSERT_EQ(f.alternatives.size(), 1u) << label;
      EXPECT_EQ(f.alternatives[0].effect, "inverter_voltage_drop");
      EXPECT_NEAR(f.alternatives[0].parameters.at("threshold_v") / c.threshold_v, 1.0, 0.15) << label;
    }
    if (c.slope_ohm > 0) {
      const Finding& f = *Find(*r, "stator_resistance");
      ASSERT_EQ(f.alternatives.size(), 1u) << label;
      EXPECT_NEAR(f.alternatives[0].parameters.at("slope_ohm") / c.slope_ohm, 1.0, 0.15) << label;
    }
    for (const auto& h : r->held_out) EXPECT_TRUE(h.passed) << label << ": " << h.signal;
  }
}

// Outside the vocabulary on two-Udc sets: a switch threshold concealed with
// its row removed is fitted as a dead time, which mispredicts the held
// voltages at the second Udc (held out as a region); and the reverse.
TEST(Honesty, InverterVoltageErrorOutsideTheCatalogue) {
  struct Case {
    std::string excluded;
    uint64_t seed;
    double threshold_v, dead_time_s;
  };
  for (const auto& c : std::vector<Case>{{"inverter_voltage_drop", 94, 0.8, 0},
                                         {"inverter_voltage_drop", 95, 0.4, 0},
                                         {"dead_time", 96, 0, 1.5e-6}}) {
    sim::TwinConfig cfg;
    cfg.seed = c.seed;
    cfg.motor = sim::PerturbForProduction(cfg.motor, c.seed);
    cfg.effects.threshold_v = c.threshold_v;
    cfg.effects.dead_time_s = c.dead_time_s;
    auto simulated = sim::Simulate(cfg, sim::WithSecondUdc(sim::DefaultPlan(), 35.0));
    ASSERT_TRUE(simulated.ok());
    DiagnoseOptions opt;
    opt.excluded_effects = {c.excluded};
    auto r = Diagnose(simulated->set, opt);
    ASSERT_TRUE(r.ok());
    EXPECT_NE(r->verdict, "explained") << c.seed;
    EXPECT_NE(r->verdict, "no_mismatch") << c.seed;
    bool failed = false;
    for (const auto& h : r->held_out) failed |= h.signal == "dc_voltage_second_udc" && !h.passed;
    EXPECT_TRUE(failed || r->verdict == "unexplained") << c.seed;
  }
}

// position_sensor_harmonic, the production defect of the vocabulary: an
// angle sensor reading true + a sin(2 theta_e + phase), alone on both
// motors with three seeds each and beside the effects that share part of
// its signature (a constant offset, a dead time); amplitude within 15 %,
// phase within 0.15 rad.
TEST(Matrix, PositionSensorHarmonic) {
  struct Case {
    bool second_motor;
    uint64_t seed;
    double amplitude_rad, phase_rad, offset_rad, dead_time_s;
  };
  const std::vector<Case> cases = {
      {false, 101, 0.02, 0.7, 0, 0},   {false, 102, 0.012, -2.0, 0, 0}, {false, 103, 0.025, 2.8, 0, 0},
      {true, 104, 0.015, -1.2, 0, 0},  {true, 105, 0.02, 0.3, 0, 0},    {true, 106, 0.012, 2.5, 0, 0},
      {false, 107, 0.02, 2.0, 0.04, 0}, {true, 108, 0.02, -0.5, -0.03, 0}, {false, 109, 0.02, 0.3, 0, 1e-6},
  };
  for (const auto& c : cases) {
    auto [cfg, plan, bench_ok] = MotorOnPlan(c.second_motor, c.seed);
    ASSERT_TRUE(bench_ok);
    cfg.effects.harmonic_amplitude_rad = c.amplitude_rad;
    cfg.effects.harmonic_phase_rad = c.phase_rad;
    cfg.effects.offset_rad = c.offset_rad;
    cfg.effects.dead_time_s = c.dead_time_s;
    auto r = SimulateThenDiagnose(cfg, plan);
    ASSERT_TRUE(r.ok()) << r.status();
    const std::string label = absl::StrCat("seed ", c.seed);
    EXPECT_EQ(r->verdict, "explained") << label << Remaining(*r);
    std::set<std::string> want = {"position_sensor_harmonic"};
    if (c.offset_rad != 0) want.insert("position_offset");
    if (c.dead_time_s > 0) want.insert("dead_time");
    ASSERT_EQ(Named(*r), want) << label;
    const Finding& f = *Find(*r, "position_sensor_harmonic");
    EXPECT_NEAR(f.parameters.at("harmonic_amplitude_rad") / c.amplitude_rad, 1.0, 0.15) << label;
    // The phase to 0.15 rad (its error is the amplitude's relative error).
    EXPECT_NEAR(std::remainder(f.parameters.at("harmonic_phase_rad") - c.phase_rad, 2 * M_PI), 0.0, 0.15) << label;
    if (c.offset_rad != 0) {
      EXPECT_NEAR(Find(*r, "position_offset")->parameters.at("offset_rad"), c.offset_rad, 0.5 * M_PI / 180) << label;
    }
    for (const auto& h : r->held_out) EXPECT_TRUE(h.passed) << label << ": " << h.signal;
  }
}

// The angle harmonic with its row removed: fitted by a stand-in (unequal
// sensor gains, which also bend the HF phase with 2 theta) whose parameters
// the held DC voltages contradict, or located by its angle pattern (the HF
// residual varying as cos(2 theta_e)) and left unexplained; never explained.
TEST(Honesty, AngleSensorHarmonicOutsideTheCatalogue) {
  for (uint64_t seed : {111, 112, 113}) {
    sim::TwinConfig cfg;
    cfg.seed = seed;
    cfg.motor = sim::PerturbForProduction(cfg.motor, seed);
    cfg.effects.harmonic_amplitude_rad = 0.02;
    cfg.effects.harmonic_phase_rad = 0.7 + seed;
    auto simulated = sim::Simulate(cfg, sim::DefaultPlan());
    ASSERT_TRUE(simulated.ok());
    DiagnoseOptions opt;
    opt.excluded_effects = {"position_sensor_harmonic"};
    auto r = Diagnose(simulated->set, opt);
    ASSERT_TRUE(r.ok());
    EXPECT_NE(r->verdict, "explained") << seed;
  }
}

// One effect on a list of sets (alone, or beside the effect `other` sets
// too): each `explained` with exactly the concealed names, every held-out
// class passing; `check` judges the finding's parameters against the
// case's effects (the truth).
struct EffectCase {
  bool second_motor;
  uint64_t seed;
  std::string other;                            // "" alone
  std::function<void(sim::Effects*)> set;       // the effect and the other one
};
void ExpectNamedWithOthers(const std::string& effect, const std::vector<EffectCase>& cases,
                           const std::function<void(const Finding&, const sim::Effects&, const std::string&)>& check) {
  for (size_t k = 0; k < cases.size(); ++k) {
    const EffectCase& c = cases[k];
    auto [cfg, plan, bench_ok] = MotorOnPlan(c.second_motor, c.seed);
    ASSERT_TRUE(bench_ok);
    c.set(&cfg.effects);
    auto r = SimulateThenDiagnose(cfg, plan);
    ASSERT_TRUE(r.ok()) << r.status();
    const std::string label = absl::StrCat("seed ", c.seed);
    EXPECT_EQ(r->verdict, "explained") << label << Remaining(*r);
    std::set<std::string> want = {effect};
    if (!c.other.empty()) want.insert(c.other);
    ASSERT_EQ(Named(*r), want) << label;
    check(*Find(*r, effect), cfg.effects, label);
    for (const auto& h : r->held_out) EXPECT_TRUE(h.passed) << label << ": " << h.signal;
  }
}

// iron_loss: a resistance parallel to the magnetising branch, alone on both
// motors (three seeds each) and beside the effects that share part of its
// signature (an HF resistance in the HF, a magnet flux change in the
// steady-state voltages and torque, a dead time, a delay); R_fe within 15 %,
// down to 10 ohm (a loss current 10 % of the HF current).
TEST(Matrix, IronLoss) {
  const std::vector<EffectCase> cases = {
      {false, 120, "", [](sim::Effects* e) { e->r_fe_ohm = 10; }},
      {false, 121, "", [](sim::Effects* e) { e->r_fe_ohm = 20; }},
      {false, 122, "", [](sim::Effects* e) { e->r_fe_ohm = 40; }},
      {false, 123, "", [](sim::Effects* e) { e->r_fe_ohm = 60; }},
      {true, 124, "", [](sim::Effects* e) { e->r_fe_ohm = 20; }},
      {true, 125, "", [](sim::Effects* e) { e->r_fe_ohm = 30; }},
      {true, 126, "", [](sim::Effects* e) { e->r_fe_ohm = 50; }},
      {false, 127, "hf_resistance", [](sim::Effects* e) { e->r_fe_ohm = 25, e->r_hf_ohm = 0.03; }},
      {true, 128, "magnet_temperature", [](sim::Effects* e) { e->r_fe_ohm = 25, e->psi_pm_wb = 0.0108; }},
      {false, 129, "dead_time", [](sim::Effects* e) { e->r_fe_ohm = 25, e->dead_time_s = 1e-6; }},
      {true, 130, "sampling_delay", [](sim::Effects* e) { e->r_fe_ohm = 30, e->delay_s = 20e-6; }},
  };
  ExpectNamedWithOthers("iron_loss", cases, [](const Finding& f, const sim::Effects& truth, const std::string& label) {
    EXPECT_NEAR(f.parameters.at("r_fe_ohm") / truth.r_fe_ohm, 1.0, 0.15) << label;
  });
}

// Iron loss with its row removed: stand-ins (an HF resistance, a magnet
// flux, an offset) cannot make the HF resistance follow L^2 and the torque
// fall short of the current at once; never explained.
// The diagnosis of a set carrying an effect (`set`) whose catalogue row is
// removed: located (never `no_mismatch`) and never `explained`.
std::optional<DiagnosisReport> DiagnoseWithoutItsRow(bool second_motor, uint64_t seed,
                                                     const std::function<void(sim::Effects*)>& set,
                                                     const std::string& excluded) {
  auto [cfg, plan, bench_ok] = MotorOnPlan(second_motor, seed);
  EXPECT_TRUE(bench_ok);
  set(&cfg.effects);
  auto simulated = sim::Simulate(cfg, plan);
  EXPECT_TRUE(simulated.ok());
  if (!bench_ok || !simulated.ok()) return std::nullopt;
  DiagnoseOptions opt;
  opt.excluded_effects = {excluded};
  auto r = Diagnose(simulated->set, opt);
  EXPECT_TRUE(r.ok()) << r.status();
  if (!r.ok()) return std::nullopt;
  EXPECT_NE(r->verdict, "explained") << excluded << ", seed " << seed;
  EXPECT_NE(r->verdict, "no_mismatch") << excluded << ", seed " << seed;
  return *std::move(r);
}

TEST(Honesty, IronLossOutsideTheCatalogue) {
  for (uint64_t seed : {131, 132, 133}) {
    DiagnoseWithoutItsRow(seed == 133, seed, [](sim::Effects* e) { e->r_fe_ohm = 20; }, "iron_loss");
  }
}

// torque_loss: friction (and the transducer's zero) and drag between the
// air gap and the torque transducer, alone on both motors and beside the
// effects that also move the torque (a magnet flux, iron loss, sensor
// gains). Named alone with them, the loss at 1500 rpm within 0.04 N m of
// the truth, each parameter within 3 of its standard deviations, the refit
// lowering the residual and every held-out class passing.
TEST(Matrix, TorqueLoss) {
  auto loss = [](double friction_nm, double viscous_nm_per_rad_s) {
    return [=](sim::Effects* e) {
      e->friction_nm = friction_nm;
      e->viscous_nm_per_rad_s = viscous_nm_per_rad_s;
    };
  };
  const std::vector<EffectCase> cases = {
      {false, 140, "", loss(0.15, 0.0)},
      {false, 141, "", loss(0.08, 6e-4)},
      {true, 142, "", loss(0.2, 0.0)},
      {true, 143, "", loss(0.0, 1e-3)},
      {false, 144, "magnet_temperature", [&](sim::Effects* e) { loss(0.15, 0.0)(e), e->psi_pm_wb = 0.0108; }},
      {false, 145, "iron_loss", [&](sim::Effects* e) { loss(0.15, 0.0)(e), e->r_fe_ohm = 25; }},
      {true, 146, "current_sensor_gain", [&](sim::Effects* e) { loss(0.15, 3e-4)(e), e->gain_a = 1.02; }},
  };
  const double w = physics::RpmToMechanicalRadS(1500.0);
  ExpectNamedWithOthers("torque_loss", cases, [&](const Finding& f, const sim::Effects& truth, const std::string& label) {
    EXPECT_NEAR(f.parameters.at("friction_nm") + w * f.parameters.at("viscous_nm_per_rad_s"),
                truth.friction_nm + w * truth.viscous_nm_per_rad_s, 0.04)
        << label;
    EXPECT_NEAR(f.parameters.at("friction_nm"), truth.friction_nm, 3 * f.parameter_std.at("friction_nm")) << label;
    EXPECT_NEAR(f.parameters.at("viscous_nm_per_rad_s"), truth.viscous_nm_per_rad_s,
                3 * f.parameter_std.at("viscous_nm_per_rad_s"))
        << label;
    EXPECT_LT(f.residual_rms_after, f.residual_rms_before) << label;
  });
}

// A torque loss with its row removed: a magnet flux can lower the torque
// but not without moving the back-EMF the voltages show; located in the
// torque rows, never explained, and torque_loss first among the hypotheses
// of what remains there.
TEST(Honesty, TorqueLossOutsideTheCatalogue) {
  for (uint64_t seed : {147, 148, 149}) {
    const auto r =
        DiagnoseWithoutItsRow(seed == 149, seed, [](sim::Effects* e) { e->friction_nm = 0.15; }, "torque_loss");
    ASSERT_TRUE(r.has_value()) << seed;
    bool located = false;
    for (const auto& m : r->remaining) {
      if (m.signal != "torque") continue;
      located = true;
      ASSERT_FALSE(m.hypotheses.empty()) << seed;
      EXPECT_EQ(m.hypotheses[0].effect, "torque_loss") << seed;
    }
    EXPECT_TRUE(located) << seed << Remaining(*r);
  }
}

// The diagnosed model is a calibration: a concealed dead time diagnosed,
// the corrected data refitted through the fit's families, and its MTPA
// table within 0.1 % (of the largest current) of the table from the same
// motor recorded without the dead time; a plain fit of the distorted set
// is worse than that.
double MtpaTableDifference(const fit::Calibration& a, const fit::Calibration& b) {
  tables::MachineLimits lim;
  lim.pole_pairs = a.pole_pairs();
  lim.rs_ohm = a.rs_ohm();
  lim.i_max_a = std::min(a.MeasuredCurrentLimitA(), b.MeasuredCurrentLimitA());
  tables::TableSpec spec;
  spec.include_generating = false;
  auto ta = tables::BuildTable(a, lim, spec), tb = tables::BuildTable(b, lim, spec);
  EXPECT_TRUE(ta.ok() && tb.ok());
  if (!ta.ok() || !tb.ok()) return 1.0;
  double worst = 0;
  const auto& xa = ta->axes[0].values;
  const auto& xb = tb->axes[0].values;
  for (size_t o = 0; o < ta->outputs.size(); ++o) {
    const auto& ya = ta->outputs[o].values;
    const auto& yb = tb->outputs[o].values;
    double scale = 0;
    for (double v : ya) scale = std::max(scale, std::abs(v));
    for (size_t k = 0; k < xa.size(); ++k) {
      // b's value at a's torque (linear interpolation; the axes differ by
      // the calibrations' maximum torques).
      for (size_t j = 0; j + 1 < xb.size(); ++j) {
        if (xb[j] <= xa[k] && xa[k] <= xb[j + 1]) {
          const double t = (xa[k] - xb[j]) / (xb[j + 1] - xb[j]);
          worst = std::max(worst, std::abs(ya[k] - (yb[j] + t * (yb[j + 1] - yb[j]))) / scale);
          break;
        }
      }
    }
  }
  return worst;
}

TEST(Calibration, DiagnosedDeadTimeGivesTheCleanMotorsTables) {
  sim::TwinConfig cfg;
  cfg.seed = 5;
  cfg.motor = sim::PerturbForProduction(cfg.motor, cfg.seed);
  auto clean = sim::Simulate(cfg, sim::DefaultPlan());
  cfg.effects.dead_time_s = 2.5e-6;
  auto distorted = sim::Simulate(cfg, sim::DefaultPlan());
  ASSERT_TRUE(clean.ok() && distorted.ok());
  auto fit_plain = [](const io::RecordingSet& set) {
    auto ids = ident::IdentifySet(set, {});
    EXPECT_TRUE(ids.ok());
    return fit::Fit(fit::FitDataFromRecording(set, *ids));
  };
  auto reference = fit_plain(clean->set);
  auto plain = fit_plain(distorted->set);
  ASSERT_TRUE(reference.ok() && plain.ok());
  auto r = Diagnose(distorted->set);
  ASSERT_TRUE(r.ok());
  ASSERT_EQ(Named(*r), std::set<std::string>{"dead_time"});
  auto diagnosed = DiagnosedCalibration(*r);
  ASSERT_TRUE(diagnosed.ok()) << diagnosed.status();
  const double d_diag = MtpaTableDifference(*reference, *diagnosed);
  const double d_plain = MtpaTableDifference(*reference, *plain);
  EXPECT_LT(d_diag, 0.001) << "diagnosed calibration's MTPA table vs the clean motor's";
  EXPECT_GT(d_plain, 2 * d_diag) << "the plain fit carries the dead time's distortion";
  std::printf("MTPA table vs clean motor: diagnosed %.4f %%, plain fit %.4f %%\n", 100 * d_diag, 100 * d_plain);
}

// The same for a torque loss: a transducer reading 0.3 N m below the air
// gap pulls the plain fit's surfaces (the fit weighs the rows' torque), the
// diagnosed calibration adds the loss back and holds the machine's flux
// and air-gap torque at the truth's steady-state points.
TEST(Calibration, DiagnosedTorqueLossGivesTheAirGapSurfaces) {
  sim::TwinConfig cfg;
  cfg.seed = 71;
  cfg.motor = sim::PerturbForProduction(cfg.motor, cfg.seed);
  cfg.effects.friction_nm = 0.3;
  auto simulated = sim::Simulate(cfg, sim::DefaultPlan());
  ASSERT_TRUE(simulated.ok());
  auto ids = ident::IdentifySet(simulated->set, {});
  ASSERT_TRUE(ids.ok());
  auto plain = fit::Fit(fit::FitDataFromRecording(simulated->set, *ids));
  auto r = Diagnose(simulated->set);
  ASSERT_TRUE(plain.ok() && r.ok());
  ASSERT_EQ(Named(*r), std::set<std::string>{"torque_loss"});
  auto diagnosed = DiagnosedCalibration(*r);
  ASSERT_TRUE(diagnosed.ok()) << diagnosed.status();
  auto torque_rms = [&](const fit::Calibration& c) {
    double e = 0;
    for (const auto& t : simulated->truth_steady_state) {
      const auto f = c.Flux(t.id_true_a, t.iq_true_a);
      e += std::pow(
          physics::ElectromagneticTorque(cfg.motor.pole_pairs, f.psi_d_wb, f.psi_q_wb, t.id_true_a, t.iq_true_a) -
              t.torque_nm,
          2);
    }
    return std::sqrt(e / simulated->truth_steady_state.size());
  };
  const double t_diag = torque_rms(*diagnosed), t_plain = torque_rms(*plain);
  EXPECT_LT(t_diag, 0.02) << "diagnosed calibration's air-gap torque at the rows, N m";
  EXPECT_GT(t_plain, 5 * t_diag) << "the plain fit carries the transducer's loss";
  std::printf("air-gap torque at the steady-state rows, RMS: diagnosed %.4f N m, plain fit %.4f N m\n", t_diag,
              t_plain);
}

// The independent generator's sets: expected verdict and effects from the
// truth files (never their motor section).
TEST(Examples, IndependentSets) {
  const fs::path root = fluxcal::testing::SharedExamplesDir();
  if (auto why = fluxcal::testing::MissingSharedExamples({"clean", "dead_time", "cross_saturation"},
                                                "Matrix.CleanSetsHaveNoFindings, Matrix.EachEffectAlone (twin sets)");
      !why.empty()) {
    GTEST_SKIP() << why;
  }
  for (const char* name : {"clean", "dead_time", "cross_saturation"}) {
    std::ifstream tf(root / (std::string(name) + ".truth.json"));
    const auto truth = nlohmann::json::parse(tf);
    auto set = io::ReadRecordingSet((root / name).string());
    ASSERT_TRUE(set.ok());
    auto r = Diagnose(*set);
    ASSERT_TRUE(r.ok());
    // Cross saturation is the machine's magnetics, which the baseline (the
    // set's own calibration) holds: the generator's cross-saturated motor
    // has nothing missing (docs/diagnosis.md, "The baseline").
    const bool own_magnetics = std::string(name) == "cross_saturation";
    EXPECT_EQ(r->verdict, own_magnetics ? "no_mismatch" : truth["expected_verdict"].get<std::string>()) << name;
    std::set<std::string> want;
    for (const auto& e : truth["concealed_effects"]) {
      if (e["effect"] != "cross_saturation") want.insert(e["effect"].get<std::string>());
    }
    EXPECT_EQ(Named(*r), want) << name;
    for (const auto& e : truth["concealed_effects"]) {
      if (e["effect"] == "dead_time") {
        const Finding* f = Find(*r, "dead_time");
        ASSERT_NE(f, nullptr);
        EXPECT_NEAR(f->parameters.at("dead_time_s") / e["parameters"]["dead_time_s"].get<double>(), 1.0, 0.2);
      }
    }
    // Its time is a benchmark's (bench/diagnosis_bench.cc, docs/performance.md),
    // not an assertion: on a loaded 2-core machine it is no figure of merit.
    // Waveform evidence: replaying every test through the twin, the final
    // model reproduces the recorded currents far better when it found
    // something, and no worse when it found nothing.
    if (want.empty()) {
      EXPECT_NEAR(r->waveform_rms_after_a, r->waveform_rms_before_a, 1e-9) << name;
      EXPECT_TRUE(r->remaining.empty()) << name;
    } else {
      EXPECT_LT(r->waveform_rms_after_a, r->waveform_rms_before_a / 3) << name;
      EXPECT_FALSE(r->significant_hz_before.empty()) << name << ": located in frequency";
      EXPECT_LT(r->significant_hz_after.size(), r->significant_hz_before.size()) << name;
    }
    EXPECT_EQ(r->spectrum_hz.size(), r->spectrum_after_a.size());
  }
}

// The calibration of the true motor from a truth file's per-point flux
// linkages and differential inductances, fitted through the same families.
absl::StatusOr<fit::Calibration> TrueMotorCalibration(const nlohmann::json& truth, const io::Manifest& mf,
                                                      const std::string& model = "auto") {
  fit::FitData t;
  t.serial = mf.serial;
  t.pole_pairs = mf.motor.pole_pairs;
  double psi_max = 0;
  for (const auto& p : truth["points"]) {
    psi_max = std::max(psi_max, std::hypot(p["psi_d_wb"].get<double>(), p["psi_q_wb"].get<double>()));
  }
  for (const auto& p : truth["points"]) {
    const double id = p["id_true_a"].get<double>(), iq = p["iq_true_a"].get<double>();
    t.fluxes.push_back({id, iq, p["psi_d_wb"].get<double>(), p["psi_q_wb"].get<double>(), 1e-4 * psi_max});
    fit::InductanceObservation o;
    o.id_a = id;
    o.iq_a = iq;
    o.ldd_h = p["ldd_h"].get<double>();
    o.lqq_h = p["lqq_h"].get<double>();
    o.ldq_h = p["ldq_h"].is_number() ? p["ldq_h"].get<double>() : 0.0;
    o.ldd_h_std = 1e-3 * o.ldd_h;
    o.lqq_h_std = 1e-3 * o.lqq_h;
    o.ldq_h_std = 1e-3 * o.lqq_h;
    t.inductances.push_back(o);
  }
  fit::FitOptions options;
  options.model = model;
  return fit::Fit(t, options);
}

// The check on the independent example: `diagnose dead_time
// --calibration-out` then export gives tables near the clean motor's. The
// clean motor is the truth file's per-point flux linkages and inductances
// (checks, not inputs: the generator's motor model is not read). The
// diagnosed calibration lands as near the true motor as a plain fit of the
// example recorded without the dead time lands near its own true motor;
// the plain fit of the dead-time set is 30x farther.
TEST(Examples, DiagnosedDeadTimeTablesAgainstTheTrueMotor) {
  const fs::path root = fluxcal::testing::SharedExamplesDir();
  if (auto why = fluxcal::testing::MissingSharedExamples({"dead_time", "clean"},
                                                "Calibration.DiagnosedDeadTimeGivesTheCleanMotorsTables (twin sets)");
      !why.empty()) {
    GTEST_SKIP() << why;
  }
  auto plain_fit = [](const io::RecordingSet& set) {
    auto ids = ident::IdentifySet(set, {});
    EXPECT_TRUE(ids.ok());
    return fit::Fit(fit::FitDataFromRecording(set, *ids));
  };
  double d[3];   // diagnosed dead_time, plain dead_time, plain clean: vs their true motors
  for (const char* name : {"dead_time", "clean"}) {
    std::ifstream tf(root / (std::string(name) + ".truth.json"));
    const auto truth = nlohmann::json::parse(tf);
    auto set = io::ReadRecordingSet((root / name).string());
    ASSERT_TRUE(set.ok());
    auto true_motor = TrueMotorCalibration(truth, set->manifest);
    auto plain = plain_fit(*set);
    ASSERT_TRUE(true_motor.ok() && plain.ok());
    if (std::string(name) == "clean") {
      d[2] = MtpaTableDifference(*true_motor, *plain);
      continue;
    }
    auto r = Diagnose(*set);
    ASSERT_TRUE(r.ok());
    auto diagnosed = DiagnosedCalibration(*r);
    ASSERT_TRUE(diagnosed.ok()) << diagnosed.status();
    d[0] = MtpaTableDifference(*true_motor, *diagnosed);
    d[1] = MtpaTableDifference(*true_motor, *plain);
    // How well the reference itself is known: the same truth points
    // through the polynomial family instead of `auto`'s choice.
    auto other = TrueMotorCalibration(truth, set->manifest, "poly");
    ASSERT_TRUE(other.ok()) << other.status();
    std::printf("true-motor reference: %s vs %s differ by %.4f %%; diagnosed vs the %s one %.4f %%\n",
                true_motor->family().Name().c_str(), other->family().Name().c_str(),
                100 * MtpaTableDifference(*true_motor, *other), other->family().Name().c_str(),
                100 * MtpaTableDifference(*other, *diagnosed));
  }
  std::printf("examples, MTPA table vs the true motor: dead_time diagnosed %.4f %%, dead_time plain fit %.4f %%, "
              "clean plain fit %.4f %%\n", 100 * d[0], 100 * d[1], 100 * d[2]);
  EXPECT_LT(d[0], 0.001) << "the issue's 0.1 %";
  EXPECT_LT(d[0], 1.5 * d[2] + 0.0002) << "as near as a clean recording's fit";
  EXPECT_GT(d[1], 10 * d[0]) << "the plain fit carries the dead time's distortion";
}

// A plain fit of each independent example set that conceals nothing in
// its magnetics' path (clean, cross saturation) against its true motor:
// the MTPA table within 0.2 % (docs/fitting.md quotes these figures:
// 0.098 % and 0.120 %).
TEST(Examples, PlainFitTablesAgainstTheTrueMotor) {
  const fs::path root = fluxcal::testing::SharedExamplesDir();
  if (auto why = fluxcal::testing::MissingSharedExamples({"clean", "cross_saturation"},
                                                "fitting_test Fit.RecoversTruthWithinHalfPercent (twin set)");
      !why.empty()) {
    GTEST_SKIP() << why;
  }
  for (const char* name : {"clean", "cross_saturation"}) {
    std::ifstream tf(root / (std::string(name) + ".truth.json"));
    const auto truth = nlohmann::json::parse(tf);
    auto set = io::ReadRecordingSet((root / name).string());
    ASSERT_TRUE(set.ok()) << set.status();
    auto true_motor = TrueMotorCalibration(truth, set->manifest);
    ASSERT_TRUE(true_motor.ok()) << true_motor.status();
    auto ids = ident::IdentifySet(*set, {});
    ASSERT_TRUE(ids.ok()) << ids.status();
    auto plain = fit::Fit(fit::FitDataFromRecording(*set, *ids));
    ASSERT_TRUE(plain.ok()) << plain.status();
    const double e = MtpaTableDifference(*true_motor, *plain);
    std::printf("examples, MTPA table vs the true motor: %s plain fit %.4f %%\n", name, 100 * e);
    EXPECT_LT(e, 0.002) << name;
  }
}

// A dead time the manifest declares uncompensated belongs to the nominal
// model: the same recording is then no longer a mismatch.
TEST(Nominal, DeclaredUncompensatedDeadTimeIsNotAFinding) {
  sim::TwinConfig cfg;
  cfg.seed = 41;
  cfg.effects.dead_time_s = 2e-6;
  sim::Plan plan = sim::DefaultPlan();
  auto sim = sim::Simulate(cfg, plan);
  ASSERT_TRUE(sim.ok());
  io::RecordingSet set = sim->set;
  set.manifest.drive.dead_time_compensated = false;
  set.manifest.drive.dead_time_s = 2e-6;
  auto r = Diagnose(set);
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->verdict, "no_mismatch");
  EXPECT_TRUE(r->findings.empty()) << r->findings[0].effect << " " << nlohmann::json(r->findings[0].parameters).dump();
}

// The plots: one coloured, labelled cell per standstill point and signal
// in the residual maps,
// red (>= 5 sigma) before and none after for a concealed dead time; in the
// spectrum, every bin of both spectra either a bar or a mark on the log
// axis's floor, no bar below that floor.
TEST(Plots, ResidualMapsAndSpectrum) {
  sim::TwinConfig cfg;
  cfg.seed = 42;
  cfg.effects.dead_time_s = 2e-6;
  auto sim = sim::Simulate(cfg, sim::DefaultPlan());
  ASSERT_TRUE(sim.ok());
  auto r = Diagnose(sim->set);
  ASSERT_TRUE(r.ok());
  size_t standstill = 0;
  for (const auto& z : r->residuals) {
    if (z.speed_rpm == 0 && (z.signal == "hf_current" || z.signal == "dc_voltage")) ++standstill;
  }
  // Cells (class "cell") by fill, and their labels.
  struct Cells {
    size_t total = 0, red = 0, labels = 0;
  };
  auto cells = [](const std::string& svg) {
    tinyxml2::XMLDocument doc;
    EXPECT_EQ(doc.Parse(svg.c_str()), tinyxml2::XML_SUCCESS) << doc.ErrorStr();
    Cells c;
    std::function<void(const tinyxml2::XMLElement*)> walk = [&](const tinyxml2::XMLElement* e) {
      for (auto* k = e->FirstChildElement(); k; k = k->NextSiblingElement()) {
        const char* cls = k->Attribute("class");
        if (cls && std::string(cls) == "cell") {
          ++c.total;
          c.red += std::string(k->Attribute("fill")) == "#ee5555";
        }
        if (cls && std::string(cls) == "cell-label") ++c.labels;
        walk(k);
      }
    };
    if (doc.RootElement()) walk(doc.RootElement());
    return c;
  };
  const Cells before = cells(ResidualMapSvg(*r, false)), after = cells(ResidualMapSvg(*r, true));
  EXPECT_EQ(before.total, standstill);
  EXPECT_EQ(after.total, standstill);
  EXPECT_EQ(before.labels, before.total) << "every cell labelled with its |z|";
  EXPECT_GT(before.red, standstill / 4) << "the dead time's DC-voltage signature, red";
  EXPECT_EQ(after.red, 0u) << "explained: nothing red after";

  tinyxml2::XMLDocument sdoc;
  const std::string spectrum = SpectrumSvg(*r);
  ASSERT_EQ(sdoc.Parse(spectrum.c_str()), tinyxml2::XML_SUCCESS) << sdoc.ErrorStr();
  const auto* clip = sdoc.RootElement()->FirstChildElement("defs")->FirstChildElement("clipPath")->FirstChildElement("rect");
  const double floor_px = clip->DoubleAttribute("y") + clip->DoubleAttribute("height");
  std::map<std::string, size_t> per_colour;   // bars and floor marks per series
  std::function<void(const tinyxml2::XMLElement*)> walk = [&](const tinyxml2::XMLElement* e) {
    for (auto* k = e->FirstChildElement(); k; k = k->NextSiblingElement()) {
      const char* cls = k->Attribute("class");
      if (cls && std::string(cls) == "bar") {
        ++per_colour[k->Attribute("fill")];
        EXPECT_LE(k->DoubleAttribute("y") + k->DoubleAttribute("height"), floor_px + 0.05) << "bar below the floor";
      }
      if (cls && std::string(cls) == "below-floor") ++per_colour[k->Attribute("fill")];
      walk(k);
    }
  };
  walk(sdoc.RootElement());
  EXPECT_EQ(per_colour["#cc3333"], r->spectrum_hz.size()) << "nominal model";
  EXPECT_EQ(per_colour["#3366cc"], r->spectrum_hz.size()) << "final model";
}

// A bench run on a real machine's measured magnetics (an independent
// simulator whose motor is a co-energy surface fitted to the measured map):
// its saturation and cross saturation are the machine's, never findings;
// a concealed dead time is found alone and the diagnosed calibration is
// closer to the measured map than the plain fit (the map itself is in the
// repository, data/real/; the bench sets are not: skipped without them).
TEST(Examples, RealMagneticsBenchSets) {
  const fs::path root = fs::path(FLUXCAL_SHARED_DIR) / "examples" / "real";
  if (!fs::exists(root / "baldor_bench_clean") || !fs::exists(root / "baldor_bench_dead_time")) {
    GTEST_SKIP() << "no shared examples/real bench sets beside the repository";
  }
  auto map = io::ReadFluxMapCsv((fs::path(FLUXCAL_SOURCE_DIR) / "data" / "real" / "baldor_fluxmap_measured.csv").string());
  ASSERT_TRUE(map.ok()) << map.status();
  for (const char* name : {"baldor_bench_clean", "baldor_bench_dead_time"}) {
    std::ifstream tf(root / (std::string(name) + ".truth.json"));
    const auto truth = nlohmann::json::parse(tf);
    auto set = io::ReadRecordingSet((root / name).string());
    ASSERT_TRUE(set.ok());
    auto r = Diagnose(*set);
    ASSERT_TRUE(r.ok()) << r.status();
    EXPECT_EQ(r->verdict, truth["expected_verdict"].get<std::string>()) << name << Remaining(*r);
    std::set<std::string> want;
    for (const auto& e : truth["concealed_effects"]) want.insert(e["effect"].get<std::string>());
    EXPECT_EQ(Named(*r), want) << name;
    if (want.empty()) continue;
    const double td = truth["concealed_effects"][0]["parameters"]["dead_time_s"].get<double>();
    EXPECT_NEAR(Find(*r, "dead_time")->parameters.at("dead_time_s") / td, 1.0, 0.02) << name;
    // The diagnosed calibration against the plain fit, over the region the
    // bench measured (id -16..0 A, iq 0..20.8 A): flux RMS relative to the
    // largest |psi| there.
    auto diagnosed = DiagnosedCalibration(*r);
    ASSERT_TRUE(diagnosed.ok()) << diagnosed.status();
    std::vector<ident::HfPointResult> ids;
    auto identified = ident::IdentifySet(*set, {});
    ASSERT_TRUE(identified.ok());
    auto plain = fit::Fit(fit::FitDataFromRecording(*set, *identified));
    ASSERT_TRUE(plain.ok());
    auto rms = [&](const fit::Calibration& c) {
      double s2 = 0, scale = 0;
      int n = 0;
      for (const auto& p : map->Points()) {
        if (p.id_a < -16 || p.id_a > 0 || p.iq_a < 0 || p.iq_a > 21) continue;
        const auto f = c.Flux(p.id_a, p.iq_a);
        s2 += std::pow(f.psi_d_wb - p.psi_d_wb, 2) + std::pow(f.psi_q_wb - p.psi_q_wb, 2);
        scale = std::max(scale, std::hypot(p.psi_d_wb, p.psi_q_wb));
        ++n;
      }
      return std::sqrt(s2 / n) / scale;
    };
    const double d = rms(*diagnosed), p = rms(*plain);
    std::printf("%s: flux RMS against the measured map, diagnosed %.3f %%, plain fit %.3f %%\n", name, 100 * d, 100 * p);
    EXPECT_LT(d, p) << name;
    EXPECT_LT(d, 0.005) << name;
  }
}

// A magnet that warms during the test is reported as a drift: psi_pm at the
// first and the last steady-state row, each within 0.3 % of the truth.
TEST(Matrix, MagnetTemperatureDrift) {
  for (uint64_t seed : {41u, 42u}) {
    sim::TwinConfig cfg;
    cfg.seed = seed;
    cfg.motor = sim::PerturbForProduction(cfg.motor, seed);
    cfg.effects.magnet_temp_rise_k = 30.0;
    auto simulated = sim::Simulate(cfg, sim::DefaultPlan());
    ASSERT_TRUE(simulated.ok());
    auto r = Diagnose(simulated->set);
    ASSERT_TRUE(r.ok());
    const Finding* f = Find(*r, "magnet_temperature");
    ASSERT_NE(f, nullptr) << "seed " << seed << ": verdict " << r->verdict;
    ASSERT_TRUE(f->parameters.count("psi_pm_start_wb")) << "a drift reported as one value";
    const auto& rows = simulated->truth_steady_state;
    EXPECT_NEAR(f->parameters.at("psi_pm_start_wb") / rows.front().psi_pm_wb, 1.0, 0.003) << "seed " << seed;
    EXPECT_NEAR(f->parameters.at("psi_pm_end_wb") / rows.back().psi_pm_wb, 1.0, 0.003) << "seed " << seed;
    EXPECT_EQ(r->verdict, "explained") << "seed " << seed;
  }
}

TEST(Table1, DifferentialInductanceFromPublishedData) {
  auto rows = ReadTable1(std::string(FLUXCAL_SOURCE_DIR) + "/data/paper_table1.csv");
  ASSERT_TRUE(rows.ok()) << rows.status();
  ASSERT_EQ(rows->size(), 6u);
  const auto r = DiagnoseTable1(*rows);
  EXPECT_EQ(r.finding, "differential_inductance");
  EXPECT_LT(r.trend_slope_per_a, 0.0) << "mismatch grows (negatively) with current";
  EXPECT_LT(r.rms_after, r.rms_before);
  // What is left (max 5.0 %) is mostly one common factor: the integrated HF
  // values are 2.6 % above the steady-state ones at every current (a
  // common scale or an additive HF bias, indistinguishable on five rows),
  // not a voltage offset growing as 1/iq.
  ASSERT_EQ(r.alternatives.size(), 4u);
  EXPECT_NEAR(r.max_after, 0.050, 0.001);
  const auto& scale = r.alternatives[1];
  EXPECT_EQ(scale.name, "common_scale");
  EXPECT_NEAR(scale.parameter, 0.974, 0.002);
  EXPECT_LT(scale.max, 0.025);
  EXPECT_LT(scale.delta_bic, -2.0);
  EXPECT_NEAR(r.alternatives[2].delta_bic, scale.delta_bic, 2.0) << "bias and scale alike on this data";
  EXPECT_GT(r.alternatives[3].delta_bic, scale.delta_bic + 2.0) << "a voltage offset explains less";
  std::printf("Table 1: RMS error %.2f %% (differential as apparent) -> %.2f %% (integrated)\n",
              100 * r.rms_before, 100 * r.rms_after);
}

}  // namespace
}  // namespace fluxcal::diag
