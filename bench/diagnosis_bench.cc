// Diagnosis of a simulated 36-point set (plus rotating points and
// steady-state rows) with a concealed dead time. Run:
//   ./build/bench/diagnosis_bench --benchmark_min_time=1
#include <string>

#include "benchmark/benchmark.h"
#include "diagnosis/diagnose.h"
#include "simulation/twin.h"

namespace {

void BM_Diagnose(benchmark::State& state) {
  fluxcal::sim::TwinConfig cfg;
  cfg.effects.dead_time_s = 2e-6;
  static auto sim = fluxcal::sim::Simulate(cfg, fluxcal::sim::DefaultPlan());
  for (auto _ : state) {
    auto r = fluxcal::diag::Diagnose(sim->set);
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK(BM_Diagnose)->Unit(benchmark::kMillisecond);

// The second motor on the EOL-like plan (42 points, 20 steady-state rows)
// with a DC-link sense error and a current-sensor offset concealed: the
// catalogue's extensions, stepwise selection and held-out refits.
void BM_DiagnoseEolExtensionsPair(benchmark::State& state) {
  fluxcal::sim::TwinConfig cfg;
  // The repository's data/ beside bench/ (this file's own path).
  std::string data = __FILE__;
  data = data.substr(0, data.rfind("/bench/")) + "/data/";
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
  for (auto _ : state) {
    auto r = fluxcal::diag::Diagnose(sim->set);
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK(BM_DiagnoseEolExtensionsPair)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
