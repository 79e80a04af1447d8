// Diagnosis of a simulated 36-point set (plus rotating points and
// steady-state rows) with a concealed dead time. Run:
//   ./build/bench/diagnosis_bench --benchmark_min_time=1
#include <filesystem>
#include <string>

#include "benchmark/benchmark.h"
#include "diagnosis/diagnose.h"
#include "io/recording_set.h"
#include "simulation/bench_effect.h"
#include "simulation/twin.h"

namespace {

// The timed loop of every benchmark here: set diagnosed.
void TimeDiagnose(benchmark::State& state, const fluxcal::io::RecordingSet& set) {
  for (auto _ : state) {
    auto r = fluxcal::diag::Diagnose(set);
    benchmark::DoNotOptimize(r);
  }
}

void BM_Diagnose(benchmark::State& state) {
  fluxcal::sim::TwinConfig cfg;
  cfg.effects.dead_time_s = 2e-6;
  static auto sim = fluxcal::sim::Simulate(cfg, fluxcal::sim::DefaultPlan());
  TimeDiagnose(state, sim->set);
}
BENCHMARK(BM_Diagnose)->Unit(benchmark::kMillisecond);

// The second motor on the EOL-like plan (42 points, 20 steady-state rows)
// with a DC-link sense error and a current-sensor offset concealed: the
// catalogue's extensions, stepwise selection and held-out refits.
void BM_DiagnoseEolExtensionsPair(benchmark::State& state) {
  fluxcal::sim::TwinConfig cfg;
  const std::string data = std::string(FLUXCAL_SOURCE_DIR) + "/data/";
  if (!fluxcal::sim::LoadMotorJson(data + "motors/second_motor.json", &cfg).ok()) {
    state.SkipWithError("second_motor.json");
    return;
  }
  auto plan = fluxcal::sim::LoadPlanJson(data + "plans/eol_like_plan.json");
  if (!plan.ok()) {
    state.SkipWithError("eol_like_plan.json");
    return;
  }
  cfg.effects.udc_sense_gain = 1.03;
  cfg.effects.offset_b_a = 1.2;
  static auto sim = fluxcal::sim::Simulate(cfg, *plan);
  TimeDiagnose(state, sim->set);
}
BENCHMARK(BM_DiagnoseEolExtensionsPair)->Unit(benchmark::kMillisecond);

// Physics outside the catalogue (simulation/bench_effects/): rotor
// eccentricity, located in the waveforms and left unexplained -- the
// waveform locator's replays of every point before and after.
void BM_DiagnoseOutsideTheCatalogue(benchmark::State& state) {
  fluxcal::sim::TwinConfig cfg;
  cfg.seed = 31;
  cfg.motor = fluxcal::sim::PerturbForProduction(cfg.motor, 31);
  if (!fluxcal::sim::SetBenchEffectParameter("eccentricity", 0.03, &cfg.effects.unmodelled).ok()) {
    state.SkipWithError("eccentricity");
    return;
  }
  static auto sim = fluxcal::sim::Simulate(cfg, fluxcal::sim::DefaultPlan());
  TimeDiagnose(state, sim->set);
}
BENCHMARK(BM_DiagnoseOutsideTheCatalogue)->Unit(benchmark::kMillisecond);

// A bench on a measured machine's magnetics with a concealed dead time
// (../shared/examples/real/baldor_bench_dead_time, beside the repository;
// skipped without it): the set's own spline calibration as baseline.
void BM_DiagnoseRealMagneticsBench(benchmark::State& state) {
  const std::string root = std::string(FLUXCAL_SHARED_DIR) + "/examples/real/baldor_bench_dead_time";
  if (!std::filesystem::exists(root)) {
    state.SkipWithError("no ../shared/examples/real/baldor_bench_dead_time");
    return;
  }
  static auto set = fluxcal::io::ReadRecordingSet(root);
  if (!set.ok()) {
    state.SkipWithError("baldor_bench_dead_time does not read");
    return;
  }
  TimeDiagnose(state, *set);
}
BENCHMARK(BM_DiagnoseRealMagneticsBench)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
