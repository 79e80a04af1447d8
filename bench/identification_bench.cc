// Throughput of the HF demodulators on one core, in samples per second
// (a sample = ia, ib, ic, theta_e). Run:
//   ./build/bench/identification_bench --benchmark_min_time=1
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "benchmark/benchmark.h"
#include "identification/demod.h"
#include "identification/demod_kernels.h"

namespace {

struct Data {
  std::vector<double> ia, ib, ic, th;
};

Data MakeData(size_t n, double speed_rad_s) {
  Data d;
  std::mt19937_64 rng(1);
  std::normal_distribution<double> nd(0, 0.05);
  const double w = 2 * std::numbers::pi * 500;
  for (size_t k = 0; k < n; ++k) {
    const double t = k * 1e-4;
    const double th = 0.4 + speed_rad_s * t;
    const double a = 6 * std::cos(w * t) + 2 * std::cos(2 * th - w * t) + 30 * std::cos(th);
    const double b = 6 * std::sin(w * t) + 2 * std::sin(2 * th - w * t) + 30 * std::sin(th);
    d.ia.push_back(a + nd(rng));
    d.ib.push_back(-0.5 * a + 0.8660254 * b + nd(rng));
    d.ic.push_back(-0.5 * a - 0.8660254 * b + nd(rng));
    // As an encoder reports it: 4096 counts per mechanical revolution, 4
    // pole pairs (the recordings' angles are quantised like this).
    const double count = 2 * std::numbers::pi * 4 / 4096;
    d.th.push_back(std::remainder(std::round(th / count) * count, 2 * std::numbers::pi));
  }
  return d;
}

// range(0): samples; range(1): 1 = rotating at 1000 rpm (4 pole pairs),
// 0 = locked rotor (the angle sensor reads one count).
void BM_Lsq(benchmark::State& state) {
  const Data d = MakeData(static_cast<size_t>(state.range(0)), state.range(1) ? 418.9 : 0.0);
  fluxcal::ident::PhaseSamples s{d.ia.data(), d.ib.data(), d.ic.data(), d.th.data(), d.ia.size(),
                                 10000.0, 500.0};
  for (auto _ : state) {
    auto e = fluxcal::ident::LsqDemodulate(s);
    benchmark::DoNotOptimize(e);
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_Lsq)->Args({1000, 0})->Args({100000, 0})->Args({1000, 1})->Args({100000, 1});

void BM_Paper(benchmark::State& state) {
  const Data d = MakeData(static_cast<size_t>(state.range(0)), state.range(1) ? 418.9 : 0.0);
  fluxcal::ident::PhaseSamples s{d.ia.data(), d.ib.data(), d.ic.data(), d.th.data(), d.ia.size(),
                                 10000.0, 500.0};
  for (auto _ : state) {
    auto e = fluxcal::ident::PaperDemodulate(s, true);
    benchmark::DoNotOptimize(e);
  }
  state.SetItemsProcessed(state.iterations() * state.range(0));
}
BENCHMARK(BM_Paper)->Args({1000, 0})->Args({100000, 0})->Args({1000, 1})->Args({100000, 1});

// The kernels alone, per instruction set (range(0): 0 baseline, 1 AVX2,
// 2 AVX-512), 100 000 samples at 1000 rpm. The public demodulators above run
// the widest set the CPU supports.
using fluxcal::ident::kernels::Isa;
bool UseIsa(benchmark::State& state, Isa* isa) {
  *isa = static_cast<Isa>(state.range(0));
  state.SetLabel(fluxcal::ident::kernels::IsaName(*isa));
  if (!fluxcal::ident::kernels::IsaSupported(*isa)) {
    state.SkipWithError("instruction set not supported by this CPU");
    return false;
  }
  return true;
}

fluxcal::ident::kernels::PhaseArrays Arrays(const Data& d) {
  return {d.ia.data(), d.ib.data(), d.ic.data(), d.th.data(), d.ia.size()};
}

// kernel(arrays, isa) timed over 100 000 samples at 1000 rpm with range(0)'s
// instruction set.
template <class Kernel>
void TimeKernel(benchmark::State& state, Kernel kernel) {
  Isa isa;
  if (!UseIsa(state, &isa)) return;
  const Data d = MakeData(100000, 418.9);
  const auto a = Arrays(d);
  for (auto _ : state) {
    auto sums = kernel(a, isa);
    benchmark::DoNotOptimize(sums);
  }
  state.SetItemsProcessed(state.iterations() * 100000);
}

void BM_LsqKernel(benchmark::State& state) {
  TimeKernel(state, [](const fluxcal::ident::kernels::PhaseArrays& a, Isa isa) {
    return fluxcal::ident::kernels::LsqNormalSums(a, a.n, 2 * std::numbers::pi * 0.05, 5.0, 1e-4, isa);
  });
}
BENCHMARK(BM_LsqKernel)->Arg(0)->Arg(1)->Arg(2);

void BM_PaperKernel(benchmark::State& state) {
  // 10 kHz / 500 Hz: M = 10, P = 20, as PaperDemodulate sets them.
  TimeKernel(state, [](const fluxcal::ident::kernels::PhaseArrays& a, Isa isa) {
    return fluxcal::ident::kernels::PaperFilterSums(a, 10, 20, 20, (100000 - 20) / 20, 2 * std::numbers::pi * 0.05,
                                                    isa);
  });
}
BENCHMARK(BM_PaperKernel)->Arg(0)->Arg(1)->Arg(2);

}  // namespace

BENCHMARK_MAIN();
