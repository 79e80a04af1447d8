// Simulated seconds per wall second of the twin (36-point locked grid,
// 0.1 s per point at 10 kHz, 10 RK4 sub-steps) and per-set time. Run:
//   ./build/bench/simulation_bench --benchmark_min_time=1
#include "benchmark/benchmark.h"
#include "simulation/twin.h"

namespace {

void BM_Simulate36Points(benchmark::State& state) {
  fluxcal::sim::TwinConfig cfg;
  fluxcal::sim::Plan plan = fluxcal::sim::DefaultPlan();
  plan.points.resize(36);
  plan.steady_state.clear();
  plan.settle_s = 0.0;
  plan.record_s = 0.1;
  for (auto _ : state) {
    auto r = fluxcal::sim::Simulate(cfg, plan);
    benchmark::DoNotOptimize(r);
  }
  const double simulated_s = 36 * 0.1;
  state.counters["simulated_s_per_wall_s"] =
      benchmark::Counter(simulated_s * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Simulate36Points)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
