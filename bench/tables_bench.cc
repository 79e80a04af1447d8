// Table generation: an MTPA table of at most 256 rows and a field-weakening
// table of at most 64 x 64 cells (round breakpoints) on a saturated motor
// with cross saturation, at the twin's limits; and a whole EOL motor as
// `fluxcal fit SET`, `fluxcal export cal.json --table mtpa --format h` and
// `--table fw --format cdfx` do it, through the same library calls, on the
// public bench set (data/real/baldor_eol: smoothing-spline model) and on a
// simulated EOL set (the demo's IPM-DEMO-0001: analytic model). Run:
//   ./build/bench/tables_bench --benchmark_min_time=1
#include <cstdlib>
#include <string>

#include "benchmark/benchmark.h"
#include "fitting/calibration.h"
#include "fitting/fit.h"
#include "identification/identify.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "simulation/twin.h"
#include "tables/export_rule.h"
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

// The timed loop: the table of spec built from m under Limits().
void TimeBuildTable(benchmark::State& state, const fluxcal::sim::AnalyticMotor& m,
                    const fluxcal::tables::TableSpec& spec) {
  for (auto _ : state) {
    auto t = fluxcal::tables::BuildTable(m, Limits(), spec);
    if (!t.ok()) state.SkipWithError(std::string(t.status().message()).c_str());
    benchmark::DoNotOptimize(t);
  }
}

void BM_Mtpa256(benchmark::State& state) {
  const auto m = Motor();
  fluxcal::tables::TableSpec spec;
  spec.points = 256;
  TimeBuildTable(state, m, spec);
}
BENCHMARK(BM_Mtpa256)->Unit(benchmark::kMillisecond);

void BM_FieldWeakening64x64(benchmark::State& state) {
  const auto m = Motor();
  fluxcal::tables::TableSpec spec;
  spec.kind = "fw";
  spec.points = 64;
  spec.speed_points = 64;
  TimeBuildTable(state, m, spec);
}
BENCHMARK(BM_FieldWeakening64x64)->Unit(benchmark::kMillisecond);

// ---- A whole EOL motor -------------------------------------------------

// Set 0: the public bench set (real Baldor motor, HF results and steady
// state); set 1: `fluxcal simulate --serial IPM-DEMO-0001 --seed 1 --spread`.
const fluxcal::io::RecordingSet& EolSet(int which) {
  static const fluxcal::io::RecordingSet baldor = [] {
    auto s = fluxcal::io::ReadRecordingSet(FLUXCAL_SOURCE_DIR "/data/real/baldor_eol");
    if (!s.ok()) std::abort();
    return *s;
  }();
  static const fluxcal::io::RecordingSet simulated = [] {
    fluxcal::sim::TwinConfig cfg;
    cfg.seed = 1;
    cfg.serial = "IPM-DEMO-0001";
    cfg.motor = fluxcal::sim::PerturbForProduction(cfg.motor, cfg.seed);
    auto r = fluxcal::sim::Simulate(cfg, fluxcal::sim::DefaultPlan());
    if (!r.ok()) std::abort();
    return r->set;
  }();
  return which == 0 ? baldor : simulated;
}

// `fluxcal fit SET --out cal.json`: identify, fit (model auto), write the
// JSON; the export reads it back.
fluxcal::fit::Calibration FitAndRoundTrip(const fluxcal::io::RecordingSet& set) {
  auto ids = fluxcal::ident::IdentifySet(set, {});
  if (!ids.ok()) std::abort();
  auto cal = fluxcal::fit::Fit(fluxcal::fit::FitDataFromRecording(set, *ids), {});
  if (!cal.ok()) std::abort();
  const std::string text = cal->ToJson().dump(2) + "\n";
  auto back = fluxcal::fit::Calibration::FromJson(nlohmann::json::parse(text));
  if (!back.ok()) std::abort();
  return *back;
}

// `fluxcal export cal.json --table KIND --format FMT`: the export rule's
// limits (the calibration's), the table, the file's bytes.
size_t ExportBytes(const fluxcal::fit::Calibration& cal, const char* kind, fluxcal::tables::Format fmt) {
  fluxcal::tables::TableSpec spec;
  spec.kind = kind;
  auto built = fluxcal::tables::BuildExportTable(cal, spec, {});
  if (!built.ok()) std::abort();
  auto out = fluxcal::tables::Export(built->table, fmt);
  if (!out.ok()) std::abort();
  return out->bytes.size();
}

void BM_EolFit(benchmark::State& state) {
  const auto& set = EolSet(static_cast<int>(state.range(0)));
  for (auto _ : state) benchmark::DoNotOptimize(FitAndRoundTrip(set));
}
BENCHMARK(BM_EolFit)->ArgName("set")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

void BM_EolMtpaHeader(benchmark::State& state) {
  const auto cal = FitAndRoundTrip(EolSet(static_cast<int>(state.range(0))));
  for (auto _ : state) benchmark::DoNotOptimize(ExportBytes(cal, "mtpa", fluxcal::tables::Format::kCHeader));
}
BENCHMARK(BM_EolMtpaHeader)->ArgName("set")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

void BM_EolFwCdfx(benchmark::State& state) {
  const auto cal = FitAndRoundTrip(EolSet(static_cast<int>(state.range(0))));
  for (auto _ : state) benchmark::DoNotOptimize(ExportBytes(cal, "fw", fluxcal::tables::Format::kCdfx));
}
BENCHMARK(BM_EolFwCdfx)->ArgName("set")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

// Fit, MTPA header and FW CDFX of one motor, from the set in memory.
void BM_WholeEolMotor(benchmark::State& state) {
  const auto& set = EolSet(static_cast<int>(state.range(0)));
  for (auto _ : state) {
    const auto cal = FitAndRoundTrip(set);
    benchmark::DoNotOptimize(ExportBytes(cal, "mtpa", fluxcal::tables::Format::kCHeader));
    benchmark::DoNotOptimize(ExportBytes(cal, "fw", fluxcal::tables::Format::kCdfx));
  }
}
BENCHMARK(BM_WholeEolMotor)->ArgName("set")->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
