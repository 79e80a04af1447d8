// Fit time for 36, 441 and 2601 inductance points (analytic family and the
// full BIC model selection). Run:
//   ./build/bench/fitting_bench --benchmark_min_time=1
#include <cmath>
#include <random>

#include "benchmark/benchmark.h"
#include "fitting/fit.h"
#include "simulation/twin.h"

namespace {

fluxcal::fit::FitData MakeData(int side) {
  fluxcal::sim::MotorParams mp;
  mp.sat.g_cross_h = 3e-5;
  fluxcal::sim::AnalyticMotor m(mp);
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n(0, 1);
  fluxcal::fit::FitData d;
  d.pole_pairs = mp.pole_pairs;
  d.psi_pm_prior_wb = mp.sat.psi_pm_wb;
  d.rs_ohm = mp.rs_ohm;
  for (int a = 0; a < side; ++a) {
    for (int b = 0; b < side; ++b) {
      const double id = -100.0 + 100.0 * a / (side - 1), iq = 100.0 * b / (side - 1);
      const auto L = m.Inductance(id, iq);
      fluxcal::fit::InductanceObservation o;
      o.id_a = id; o.iq_a = iq;
      o.ldd_h = L.ldd_h * (1 + 0.001 * n(rng));
      o.lqq_h = L.lqq_h * (1 + 0.001 * n(rng));
      o.ldq_h = L.ldq_h + 1e-7 * n(rng);
      o.ldd_h_std = 0.001 * L.ldd_h; o.lqq_h_std = 0.001 * L.lqq_h; o.ldq_h_std = 1e-7;
      d.inductances.push_back(o);
    }
  }
  return d;
}

void BM_FitAnalytic(benchmark::State& state) {
  const auto d = MakeData(static_cast<int>(state.range(0)));
  fluxcal::fit::FitOptions o;
  o.model = "analytic";
  for (auto _ : state) {
    auto c = fluxcal::fit::Fit(d, o);
    benchmark::DoNotOptimize(c);
  }
  state.counters["points"] = static_cast<double>(d.inductances.size());
}
BENCHMARK(BM_FitAnalytic)->Arg(6)->Arg(21)->Arg(51)->Unit(benchmark::kMillisecond);

void BM_FitAuto(benchmark::State& state) {
  const auto d = MakeData(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    auto c = fluxcal::fit::Fit(d, {});
    benchmark::DoNotOptimize(c);
  }
  state.counters["points"] = static_cast<double>(d.inductances.size());
}
BENCHMARK(BM_FitAuto)->Arg(6)->Arg(21)->Arg(51)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
