// Machines of other kinds than the twin's analytic family (closed-form
// co-energies with the traits of measured maps, simulation/trait_motor.h),
// recorded by the twin's bench on the default plan (id -100..0 A, iq
// 0..100 A): their saturation and cross saturation are their own, so a
// clean recording reads `no_mismatch`, and with a concealed dead time only
// `dead_time` is named, within 10 %, and the diagnosed calibration is at
// least as close to the true magnetics as the plain fit. The machines
// symmetric in iq: one half measured cannot tell the psi_q(id, 0) machine
// from a symmetric one (docs/fitting.md, "Symmetry").
// That includes a machine whose own inductance is not positive definite
// somewhere in the plan's region (the negative-slope map, Ldd < 0 near
// zero current): the fit leaves that point out (it cannot be followed by a
// physical surface, docs/fitting.md), and the odd harmonics of the
// injection its dip makes there are its own HF bending (the waveform
// nuisance's series, diagnosis/waveform.cc), not missing physics.
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <set>
#include <string>
#include <utility>

#include "absl/strings/str_cat.h"
#include "diagnosis/diagnose.h"
#include "fitting/fit.h"
#include "gtest/gtest.h"
#include "identification/identify.h"
#include "simulation/trait_motor.h"
#include "simulation/twin.h"

namespace fluxcal::diag {
namespace {

// Flux RMS of `cal` against the machine over the plan's region, relative to
// the largest |psi| there.
double FluxRms(const fit::Calibration& cal, const sim::MagneticModel& truth) {
  double s2 = 0, scale = 0;
  int n = 0;
  for (int i = 0; i <= 10; ++i) {
    for (int j = 0; j <= 10; ++j) {
      const double id = -100.0 + 10.0 * i, iq = 10.0 * j;
      const auto f = cal.Flux(id, iq);
      const auto t = truth.Flux(id, iq);
      s2 += std::pow(f.psi_d_wb - t.psi_d_wb, 2) + std::pow(f.psi_q_wb - t.psi_q_wb, 2);
      scale = std::max(scale, std::hypot(t.psi_d_wb, t.psi_q_wb));
      ++n;
    }
  }
  return std::sqrt(s2 / n) / scale;
}

// The diagnosed calibration's and the plain fit's flux RMS against the
// machine (FluxRms), the plain fit being `fluxcal fit` of the same
// recording; {-1, -1} when either cannot be made.
std::pair<double, double> DiagnosedAndPlainFluxRms(const DiagnosisReport& r, const io::RecordingSet& set,
                                                   const sim::MagneticModel& truth) {
  auto diagnosed = DiagnosedCalibration(r);
  EXPECT_TRUE(diagnosed.ok()) << diagnosed.status();
  auto ids = ident::IdentifySet(set, {});
  EXPECT_TRUE(ids.ok()) << ids.status();
  if (!diagnosed.ok() || !ids.ok()) return {-1, -1};
  auto plain = fit::Fit(fit::FitDataFromRecording(set, *ids));
  EXPECT_TRUE(plain.ok()) << plain.status();
  if (!plain.ok()) return {-1, -1};
  return {FluxRms(*diagnosed, truth), FluxRms(*plain, truth)};
}

// Whether the machine's inductance is positive definite over the plan's
// region (21 x 21 grid).
bool PositiveDefiniteOverPlan(const sim::MagneticModel& m) {
  for (int i = 0; i <= 20; ++i) {
    for (int j = 0; j <= 20; ++j) {
      const auto l = m.Inductance(-100.0 + 5.0 * i, 5.0 * j);
      if (l.ldd_h <= 0 || l.lqq_h <= 0 || l.ldd_h * l.lqq_h - l.ldq_h * l.ldq_h <= 0) return false;
    }
  }
  return true;
}

// The twin's seed: 11, or FLUXCAL_OTHER_MACHINES_SEED to check the tables
// on other draws of the noise (docs/diagnosis.md quotes seeds 12 and 13).
uint64_t Seed() {
  const char* e = std::getenv("FLUXCAL_OTHER_MACHINES_SEED");
  return e != nullptr ? std::strtoull(e, nullptr, 10) : 11u;
}

std::vector<sim::MotorTraits> Kinds() {
  std::vector<sim::MotorTraits> v;
  for (const auto& t : sim::RealLikeMotors(100.0, 0.15)) {
    if (t.psi_q_offset_wb == 0) v.push_back(t);
  }
  for (const auto& t : sim::OtherKindMotors(100.0, 0.15)) {
    if (t.psi_pm_wb > 0) v.push_back(t);   // the plan's speeds need a back-EMF to hold
  }
  return v;
}

TEST(OtherMachines, CleanNamesNothingDeadTimeAloneAndCloser) {
  const auto kinds = Kinds();
  ASSERT_GE(kinds.size(), 4u);
  for (const auto& t : kinds) {
    for (double dead_time_s : {0.0, 2e-6}) {
      sim::TwinConfig cfg;
      cfg.seed = Seed();
      cfg.motor.sat.psi_pm_wb = t.psi_pm_wb;
      auto truth = std::make_shared<sim::TraitMotor>(t);
      cfg.magnetics = truth;
      cfg.control.gain_scheduled = true;
      cfg.effects.dead_time_s = dead_time_s;
      auto simulated = sim::Simulate(cfg, sim::DefaultPlan());
      ASSERT_TRUE(simulated.ok()) << t.name << ": " << simulated.status();
      auto r = Diagnose(simulated->set);
      ASSERT_TRUE(r.ok()) << t.name << ": " << r.status();
      const std::string label = absl::StrCat(t.name, dead_time_s > 0 ? ", dead time 2 us" : ", clean");
      std::set<std::string> named;
      for (const auto& f : r->findings) named.insert(f.effect);
      std::string remaining;
      for (const auto& m : r->remaining) remaining += "\n  remaining " + m.signal + " " + m.kind + " at " + m.where;
      std::printf("%s: %s (replay residual %.3f A -> %.3f A)", label.c_str(), r->verdict.c_str(),
                  r->waveform_rms_before_a, r->waveform_rms_after_a);
      for (const auto& f : r->findings) std::printf(" %s", f.effect.c_str());
      if (dead_time_s == 0) {
        std::printf("\n");
        EXPECT_TRUE(named.empty()) << label << ": " << r->findings[0].effect << remaining;
        EXPECT_EQ(r->verdict, "no_mismatch") << label << remaining;
        continue;
      }
      EXPECT_EQ(named, std::set<std::string>{"dead_time"}) << label << remaining;
      // The final model replays the recording closer than the baseline
      // without the dead time (its HF ellipse at the plan's edge points
      // reaches past the measured currents: ContinuedSurface).
      EXPECT_LT(r->waveform_rms_after_a, 0.25 * r->waveform_rms_before_a) << label;
      if (const Finding* f = named.count("dead_time") ? &r->findings[0] : nullptr) {
        EXPECT_NEAR(f->parameters.at("dead_time_s") / dead_time_s, 1.0, 0.1) << label;
      }
      const auto [d, p] = DiagnosedAndPlainFluxRms(*r, simulated->set, *truth);
      std::printf("; flux RMS against the machine: diagnosed %.3f %%, plain fit %.3f %%\n", 100 * d, 100 * p);
      ASSERT_GE(d, 0) << label;
      EXPECT_LE(d, p * 1.02) << label;
    }
  }
}

// The same machines with one catalogue effect each (seed 11, default plan):
// never a wrong effect named, never `explained` without the concealed one,
// and the concealed effect named in all but one of the 42 sets -- a 5 %
// magnet flux on the negative-slope machine (its flexible surfaces take
// it where its screened-out point leaves a gap near zero current) -- and
// `explained` but for one set in ten, on every machine and on those whose
// own inductance is positive definite over the plan: the machine's own magnetics
// (saturation, cross saturation, the HF orbit's harmonics across a knee)
// are the baseline's, never a reason to leave a true finding partly
// explained. Prints the table of docs/diagnosis.md, "Beyond the measured
// currents".
TEST(OtherMachines, CatalogueEffectsNamedNeverAnother) {
  const auto kinds = Kinds();
  const std::vector<std::pair<std::string, std::string>> effects = {
      {"offset_rad=0.03", "position_offset"},     {"gain_a=1.02", "current_sensor_gain"},
      {"rs_ohm=0.0135", "stator_resistance"},     {"psi_pm -5 %", "magnet_temperature"},
      {"offset_b_a=0.6", "current_sensor_offset"}, {"delay_s=10e-6", "sampling_delay"},
      {"r_hf_ohm=0.006", "hf_resistance"}};
  int named_right = 0, explained = 0, sets = 0, positive_definite_sets = 0, explained_positive_definite = 0;
  for (const auto& t : kinds) {
    for (const auto& [spec, effect] : effects) {
      sim::TwinConfig cfg;
      cfg.seed = Seed();
      cfg.motor.sat.psi_pm_wb = t.psi_pm_wb;
      cfg.magnetics = std::make_shared<sim::TraitMotor>(t);
      cfg.control.gain_scheduled = true;
      const std::string key = effect == "magnet_temperature" ? absl::StrCat("psi_pm_wb=", 0.95 * t.psi_pm_wb) : spec;
      ASSERT_TRUE(sim::ParseEffects(key, &cfg.effects, nullptr).ok()) << key;
      auto simulated = sim::Simulate(cfg, sim::DefaultPlan());
      ASSERT_TRUE(simulated.ok()) << t.name << ": " << simulated.status();
      auto r = Diagnose(simulated->set);
      ASSERT_TRUE(r.ok()) << t.name << ": " << r.status();
      const std::string label = absl::StrCat(t.name, ", ", spec);
      std::set<std::string> named;
      for (const auto& f : r->findings) named.insert(f.effect);
      std::printf("%-32s %-17s", label.c_str(), r->verdict.c_str());
      for (const auto& f : r->findings) {
        std::printf(" %s", f.effect.c_str());
        for (const auto& [name, value] : f.parameters) std::printf(" %s=%.4g", name.c_str(), value);
      }
      std::printf(" (replay residual %.3f A -> %.3f A)\n", r->waveform_rms_before_a, r->waveform_rms_after_a);
      // Why a set is not `explained`: the held-out classes that failed and
      // what remains located (docs/diagnosis.md quotes these lines).
      for (const auto& h : r->held_out) {
        if (!h.passed) std::printf("    held out %s: %.1f sigma\n", h.signal.c_str(), h.significance_sigma);
      }
      for (const auto& m : r->remaining) {
        std::printf("    remaining %s %s, %.1f sigma: %s\n", m.signal.c_str(), m.kind.c_str(), m.significance_sigma,
                    m.where.c_str());
      }
      ++sets;
      for (const auto& n : named) EXPECT_EQ(n, effect) << label << ": named an effect that is not there";
      if (named.count(effect)) ++named_right;
      else EXPECT_NE(r->verdict, "explained") << label;
      if (r->verdict == "explained") ++explained;
      if (PositiveDefiniteOverPlan(*cfg.magnetics)) {
        ++positive_definite_sets;
        if (r->verdict == "explained") ++explained_positive_definite;
      }
    }
  }
  std::printf("seed %llu, %d sets: the concealed effect named in %d, explained %d (%d of the %d on machines positive "
              "definite over the plan)\n",
              static_cast<unsigned long long>(Seed()), sets, named_right, explained, explained_positive_definite,
              positive_definite_sets);
  // 41 of 42 since a candidate's surfaces are never rougher than the
  // current model's (docs/diagnosis.md); the one left: the negative-slope
  // machine's 5 % magnet flux.
  EXPECT_GE(named_right, sets - 1);
  EXPECT_GE(explained_positive_definite, positive_definite_sets - positive_definite_sets / 10);
  EXPECT_GE(explained, sets - sets / 10);
}

// A machine without magnets (the synchronous reluctance trait machine,
// psi_pm = 0, saliency up to 15; its axes as the PM-SyRM's: d the
// low-inductance axis, docs/fitting.md) on the same plan: clean reads
// `no_mismatch`, each concealed effect is named alone with its value, and
// the diagnosed calibration is closer to the machine than the plain fit
// where the effect bends the plain fit (dead time, angle offset, sensor
// gain and offset), and not materially worse where it does not (Rs, delay).
TEST(OtherMachines, SynchronousReluctanceMachine) {
  sim::MotorTraits t;
  for (const auto& k : sim::OtherKindMotors(100.0, 0.15)) {
    if (k.name == "syrm") t = k;
  }
  ASSERT_EQ(t.name, "syrm");
  ASSERT_EQ(t.psi_pm_wb, 0.0);
  struct Case {
    std::string spec, effect, parameter;
    double value, tolerance;
  };
  const std::vector<Case> cases = {
      {"", "", "", 0, 0},
      {"dead_time_s=2e-6", "dead_time", "dead_time_s", 2e-6, 0.05e-6},
      {"offset_rad=0.03", "position_offset", "offset_rad", 0.03, 0.002},
      {"gain_a=1.02", "current_sensor_gain", "gain_a", 1.02, 0.002},
      {"rs_ohm=0.0135", "stator_resistance", "rs_ohm", 0.0135, 0.0002},
      {"delay_s=10e-6", "sampling_delay", "delay_s", 10e-6, 0.3e-6},
      {"offset_b_a=0.6", "current_sensor_offset", "offset_b_a", 0.4, 0.02},   // zero-sum: 2/3 of 0.6
  };
  for (const auto& c : cases) {
    sim::TwinConfig cfg;
    cfg.seed = Seed();
    cfg.motor.sat.psi_pm_wb = 0.0;
    auto truth = std::make_shared<sim::TraitMotor>(t);
    cfg.magnetics = truth;
    cfg.control.gain_scheduled = true;
    if (!c.spec.empty()) ASSERT_TRUE(sim::ParseEffects(c.spec, &cfg.effects, nullptr).ok()) << c.spec;
    auto simulated = sim::Simulate(cfg, sim::DefaultPlan());
    ASSERT_TRUE(simulated.ok()) << simulated.status();
    auto r = Diagnose(simulated->set);
    ASSERT_TRUE(r.ok()) << r.status();
    const std::string label = c.spec.empty() ? "syrm, clean" : "syrm, " + c.spec;
    std::printf("%-32s %-17s", label.c_str(), r->verdict.c_str());
    for (const auto& f : r->findings) {
      std::printf(" %s", f.effect.c_str());
      for (const auto& [name, value] : f.parameters) std::printf(" %s=%.4g", name.c_str(), value);
    }
    std::printf(" (replay residual %.3f A -> %.3f A)", r->waveform_rms_before_a, r->waveform_rms_after_a);
    if (c.spec.empty()) {
      std::printf("\n");
      EXPECT_EQ(r->verdict, "no_mismatch") << label;
      EXPECT_TRUE(r->findings.empty()) << label;
      continue;
    }
    ASSERT_EQ(r->findings.size(), 1u) << label << ": " << r->verdict;
    EXPECT_EQ(r->findings[0].effect, c.effect) << label;
    EXPECT_NE(r->verdict, "unexplained") << label;
    EXPECT_NEAR(r->findings[0].parameters.at(c.parameter), c.value, c.tolerance) << label;
    const auto [d, p] = DiagnosedAndPlainFluxRms(*r, simulated->set, *truth);
    std::printf("; flux RMS: diagnosed %.3f %%, plain fit %.3f %%\n", 100 * d, 100 * p);
    ASSERT_GE(d, 0) << label;
    EXPECT_LE(d, 1.1 * p) << label;
  }
}

}  // namespace
}  // namespace fluxcal::diag
