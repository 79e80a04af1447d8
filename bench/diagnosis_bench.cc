// Diagnosis of a simulated 36-point set (plus rotating points and
// steady-state rows) with a concealed dead time. Run:
//   ./build/bench/diagnosis_bench --benchmark_min_time=1
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

}  // namespace

BENCHMARK_MAIN();
