// Table generation: an MTPA table of at most 256 rows and a field-weakening
// table of at most 64 x 64 cells (round breakpoints) on a saturated motor
// with cross saturation, at the twin's limits. Run:
//   ./build/bench/tables_bench --benchmark_min_time=1
#include <string>

#include "benchmark/benchmark.h"
#include "simulation/twin.h"
#include "tables/tables.h"

namespace {

fluxcal::sim::AnalyticMotor Motor() {
  fluxcal::sim::MotorParams p;
  p.sat.g_cross_h = 3e-5;
  return fluxcal::sim::AnalyticMotor(p);
}

// The twin's pole pairs, Rs and Udc, and a 150 A current limit.
fluxcal::tables::MachineLimits Limits() {
  fluxcal::tables::MachineLimits lim;
  lim.pole_pairs = fluxcal::sim::MotorParams().pole_pairs;
  lim.rs_ohm = fluxcal::sim::MotorParams().rs_ohm;
  lim.udc_v = fluxcal::sim::DriveParams().udc_v;
  lim.i_max_a = 150.0;
  return lim;
}

void BM_Mtpa256(benchmark::State& state) {
  const auto m = Motor();
  fluxcal::tables::TableSpec spec;
  spec.points = 256;
  for (auto _ : state) {
    auto t = fluxcal::tables::BuildTable(m, Limits(), spec);
    if (!t.ok()) state.SkipWithError(std::string(t.status().message()).c_str());
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
    auto t = fluxcal::tables::BuildTable(m, Limits(), spec);
    if (!t.ok()) state.SkipWithError(std::string(t.status().message()).c_str());
    benchmark::DoNotOptimize(t);
  }
}
BENCHMARK(BM_FieldWeakening64x64)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
