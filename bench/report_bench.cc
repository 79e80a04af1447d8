// The report page of the public Baldor EOL set (data/real/baldor_eol, the
// issue's example: a real machine, 540 V DC link), fitted once: the whole
// page (BuildReport with the set's points) and, for comparison, the three
// tables it must contain (MTPA, MTPV, field weakening as `fluxcal export`
// computes them, the page's checksums). The difference is what the page's
// own figures cost. Run:
//   ./build/bench/report_bench --benchmark_min_time=2
#include <string>

#include "benchmark/benchmark.h"
#include "fitting/fit.h"
#include "identification/identify.h"
#include "io/recording_set.h"
#include "report/report.h"
#include "tables/tables.h"

namespace {

struct Fixture {
  fluxcal::fit::FitData data;
  fluxcal::fit::Calibration cal;
  bool ok = false;
};

const Fixture& Baldor() {
  static const Fixture f = [] {
    Fixture x;
    // The repository's data/ (FLUXCAL_SOURCE_DIR, bench/CMakeLists.txt).
    absl::StatusOr<fluxcal::io::RecordingSet> set =
        fluxcal::io::ReadRecordingSet(std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_eol");
    if (!set.ok()) return x;
    x.data = fluxcal::fit::FitDataFromRecording(*set, {});
    auto cal = fluxcal::fit::Fit(x.data);
    if (!cal.ok()) return x;
    x.cal = *cal;
    x.ok = true;
    return x;
  }();
  return f;
}

// Baldor(), or nullptr with the benchmark skipped when it did not load.
const Fixture* BaldorOrSkip(benchmark::State& state) {
  const Fixture& f = Baldor();
  if (f.ok) return &f;
  state.SkipWithError("data/real/baldor_eol");
  return nullptr;
}

void BM_ReportPage(benchmark::State& state) {
  const Fixture* baldor = BaldorOrSkip(state);
  if (baldor == nullptr) return;
  const Fixture& f = *baldor;
  fluxcal::report::ReportInputs in;
  in.calibration = &f.cal;
  in.calibration_json = f.cal.ToJson();
  in.identified = &f.data;
  size_t bytes = 0;
  for (auto _ : state) {
    auto rep = fluxcal::report::BuildReport(in);
    if (!rep.ok()) state.SkipWithError(std::string(rep.status().message()).c_str());
    bytes = rep.ok() ? rep->html.size() : 0;
    benchmark::DoNotOptimize(rep);
  }
  state.counters["page_bytes"] = static_cast<double>(bytes);
}
BENCHMARK(BM_ReportPage)->Unit(benchmark::kMillisecond);

void BM_ReportTablesOnly(benchmark::State& state) {
  const Fixture* baldor = BaldorOrSkip(state);
  if (baldor == nullptr) return;
  const Fixture& f = *baldor;
  fluxcal::tables::MachineLimits lim;
  lim.pole_pairs = f.cal.pole_pairs();
  lim.rs_ohm = f.cal.rs_ohm();
  lim.udc_v = f.cal.udc_v();
  lim.i_max_a = f.cal.MeasuredCurrentLimitA();
  for (auto _ : state) {
    for (const char* kind : {"mtpa", "mtpv", "fw"}) {
      fluxcal::tables::TableSpec spec;
      spec.kind = kind;
      spec.measured_current_limit_a = lim.i_max_a;
      spec.allow_extrapolation = std::string(kind) == "mtpv";   // as the page: this MTPV lies beyond the limit
      auto t = fluxcal::tables::BuildTable(f.cal, lim, spec);
      benchmark::DoNotOptimize(t);
    }
  }
}
BENCHMARK(BM_ReportTablesOnly)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
