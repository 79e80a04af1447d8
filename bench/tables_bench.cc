// Table generation: 256-row MTPA and a 64 x 64 field-weakening table on a
// saturated motor with cross saturation. Run:
//   ./build/bench/tables_bench --benchmark_min_time=1
#include "benchmark/benchmark.h"
#include "simulation/twin.h"
#include "tables/tables.h"

namespace {

fluxcal::sim::AnalyticMotor Motor() {
  fluxcal::sim::MotorParams p;
  p.sat.g_cross_h = 3e-5;
  return fluxcal::sim::AnalyticMotor(p);
}

void BM_Mtpa256(benchmark::State& state) {
  const auto m = Motor();
  fluxcal::tables::TableSpec spec;
  spec.points = 256;
  for (auto _ : state) {
    auto t = fluxcal::tables::BuildTable(m, {}, spec);
    benchmark::DoNotOptimize(t);
  }
}
BENCHMARK(BM_Mtpa256)->Unit(benchmark::kMillisecond);

void BM_FieldWeakening64x64(benchmark::State& state) {
  const auto m = Motor();
  fluxcal::tables::TableSpec spec;
  spec.kind = "fw";
  spec.points = 64;
  spec.speed_points = 64;
  for (auto _ : state) {
    auto t = fluxcal::tables::BuildTable(m, {}, spec);
    benchmark::DoNotOptimize(t);
  }
}
BENCHMARK(BM_FieldWeakening64x64)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
