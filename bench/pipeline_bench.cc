// The stored calibration (pipeline/calibration_codec.h): encode and decode
// per model family, against the JSON it replaced, with the bytes each form
// takes per version (counters json_bytes, model_bytes); and the fleet
// measurement of docs/performance.md ("Compact calibrations"), which is not
// a Google Benchmark loop:
//
//   pipeline_bench --fleet-ingest URL VERSIONS SECONDS [FIRST]
//       appends synthetic versions (smooth-asym, the largest family, of a simulated
//       bench run, its parameters varied per version; 2 versions per motor,
//       one AddCalibration transaction each, with its audit row, as
//       FitSerial stores) until VERSIONS or SECONDS, and prints the ingest rate;
//       FIRST (even, default 0) is the index of the first version, so that
//       several processes can fill one store with disjoint motors;
//   pipeline_bench --fleet-query URL VERSIONS QUERIES
//       QueryFlux (the store's read of one version + decode + Predict at one
//       point) of QUERIES versions picked at random among the first VERSIONS
//       the ingest wrote, in a fresh process (so LoadCalibration's cache is
//       empty) that reads nothing else first, and prints p50 / p99 / max.
// Between the two the caller makes the cache cold (docs/performance.md).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "fitting/fit.h"
#include "identification/identify.h"
#include "fluxcal/v1/calibration_model.pb.h"
#include "nlohmann/json.hpp"
#include "pipeline/calibration_codec.h"
#include "pipeline/pipeline.h"
#include "pipeline/store.h"
#include "simulation/twin.h"

namespace {

using fluxcal::fit::Calibration;

const char* const kModels[] = {"analytic", "poly4", "spline3", "smooth", "smooth-asym"};

// One simulated bench run fitted with each family (as tests/pipeline's
// codec test does).
const std::map<std::string, Calibration>& Fits() {
  static const auto* fits = [] {
    auto* out = new std::map<std::string, Calibration>;
    fluxcal::sim::TwinConfig cfg;
    cfg.seed = 26;
    cfg.sensors.noise_a = 0.08;
    cfg.effects.cross_saturation = 3e-5;
    auto r = fluxcal::sim::Simulate(cfg, fluxcal::sim::DefaultPlan());
    if (!r.ok()) std::abort();
    auto ids = fluxcal::ident::IdentifySet(r->set, {});
    if (!ids.ok()) std::abort();
    const auto data = fluxcal::fit::FitDataFromRecording(r->set, *ids);
    for (const char* m : kModels) {
      fluxcal::fit::FitOptions o;
      o.model = m;
      auto cal = fluxcal::fit::Fit(data, o);
      if (!cal.ok()) std::abort();
      out->emplace(m, std::move(*cal));
    }
    return out;
  }();
  return *fits;
}

// The sizes of cal in both forms, and its model (range(0)) as the label.
void Sizes(benchmark::State& state, const Calibration& cal) {
  state.counters["json_bytes"] = static_cast<double>(cal.ToJson().dump().size());
  state.counters["model_bytes"] = static_cast<double>(fluxcal::pipeline::EncodeCalibration(cal).size());
  state.SetLabel(kModels[state.range(0)]);
}

void BM_EncodeModel(benchmark::State& state) {
  const Calibration& cal = Fits().at(kModels[state.range(0)]);
  for (auto _ : state) benchmark::DoNotOptimize(fluxcal::pipeline::EncodeCalibration(cal));
  Sizes(state, cal);
}
BENCHMARK(BM_EncodeModel)->DenseRange(0, 4)->Unit(benchmark::kMicrosecond);

void BM_DecodeModel(benchmark::State& state) {
  const Calibration& cal = Fits().at(kModels[state.range(0)]);
  const std::string bytes = fluxcal::pipeline::EncodeCalibration(cal);
  for (auto _ : state) benchmark::DoNotOptimize(fluxcal::pipeline::DecodeCalibration(bytes));
  Sizes(state, cal);
}
BENCHMARK(BM_DecodeModel)->DenseRange(0, 4)->Unit(benchmark::kMicrosecond);

// What a read cost before: the stored JSON text parsed into a Calibration.
void BM_DecodeJson(benchmark::State& state) {
  const Calibration& cal = Fits().at(kModels[state.range(0)]);
  const std::string text = cal.ToJson().dump();
  for (auto _ : state) benchmark::DoNotOptimize(Calibration::FromJson(nlohmann::json::parse(text)));
  Sizes(state, cal);
}
BENCHMARK(BM_DecodeJson)->DenseRange(0, 4)->Unit(benchmark::kMicrosecond);

// ---- The fleet measurement.

double Seconds(std::chrono::steady_clock::time_point a) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - a).count();
}

std::string Serial(int64_t k) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "FLEET-%07lld", static_cast<long long>(k));
  return buf;
}

int FleetIngest(const std::string& url, int64_t versions, double seconds, int64_t first) {
  if (first < 0 || first % 2 != 0) {
    std::fprintf(stderr, "FIRST must be even and >= 0 (two versions per motor), got %lld\n",
                 static_cast<long long>(first));
    return 1;
  }
  const Calibration& base = Fits().at("smooth-asym");   // the largest family
  auto store = fluxcal::pipeline::OpenStore(url);
  if (!store.ok()) {
    std::fprintf(stderr, "%s\n", std::string(store.status().message()).c_str());
    return 1;
  }
  std::mt19937_64 rng(26 + first);
  std::normal_distribution<double> noise(0.0, 1e-3);
  // The versions differ in their parameters only; their covariance, and so
  // its packing (float32, shuffled, deflated at zlib's best level: ~4 ms of
  // this loop's ~5 ms of CPU per version, and measured per family by
  // BM_Encode above), is the same for all. The stored bytes are made from
  // the first version's encoding with the parameters and the serial set,
  // which are the bytes EncodeCalibration writes: checked on the first
  // versions of the run, so that a change of the codec cannot make this
  // store other bytes than the service would.
  constexpr int64_t kChecked = 4;
  fluxcal::v1::CalibrationModel model;
  const auto t0 = std::chrono::steady_clock::now();
  int64_t n = 0, bytes = 0;
  for (; n < versions && Seconds(t0) < seconds; ++n) {
    const int64_t motor = (first + n) / 2;
    const std::string serial = Serial(motor);
    if ((first + n) % 2 == 0) {
      fluxcal::storage::MotorRow m{serial, 4, 0.011, 0.0114, fluxcal::pipeline::StoreNowUtc()};
      if (auto s = (*store)->ImportMotor(m); !s.ok()) {
        std::fprintf(stderr, "motor %s: %s\n", serial.c_str(), std::string(s.message()).c_str());
        return 1;
      }
    }
    // A different calibration each version: the fitted parameters varied.
    std::vector<double> p = base.params();
    for (double& v : p) v *= 1 + noise(rng);
    Calibration cal(serial, base.family(), p, base.covariance(), base.pole_pairs(), base.rs_ohm(), base.id_min_a(),
                    base.id_max_a(), base.iq_min_a(), base.iq_max_a());
    cal.summary = base.summary;
    cal.SetMeasuredIq(base.iq_halves(), base.iq_signed_min_a(), base.iq_signed_max_a());
    fluxcal::storage::CalibrationRow row;
    row.serial = serial;
    row.model = cal.family().Name();
    row.psi_pm_wb = cal.psi_pm_wb();
    row.rms_relative = cal.summary.rms_relative;
    row.verdict = "pass";
    if (n == 0) model.ParseFromString(fluxcal::pipeline::EncodeCalibration(cal));
    model.set_serial(serial);
    for (size_t i = 0; i < p.size(); ++i) model.set_params(static_cast<int>(i), cal.params()[i]);
    row.model_pb = model.SerializeAsString();
    if (n < kChecked && row.model_pb != fluxcal::pipeline::EncodeCalibration(cal)) {
      std::fprintf(stderr, "version %lld: the bytes differ from EncodeCalibration's\n", static_cast<long long>(n));
      return 1;
    }
    bytes += static_cast<int64_t>(row.model_pb.size());
    fluxcal::storage::AuditContext audit;
    audit.row = {0, "", "station-bench", "station", "127.0.0.1", "", "Fit", serial, ""};
    audit.detail = [](int64_t version, bool) { return "version " + std::to_string(version) + " (smooth-asym): pass"; };
    if (auto v = (*store)->AddCalibration(row, &audit); !v.ok()) {
      std::fprintf(stderr, "version %lld: %s\n", static_cast<long long>(n), std::string(v.status().message()).c_str());
      return 1;
    }
    if ((n + 1) % 10000 == 0) {
      std::fprintf(stderr, "%lld versions, %.0f s\n", static_cast<long long>(n + 1), Seconds(t0));
    }
  }
  const double s = Seconds(t0);
  std::printf("fleet-ingest %s: %lld versions (%lld motors) in %.1f s = %.0f versions/s; model %.0f bytes/version\n",
              url.c_str(), static_cast<long long>(n), static_cast<long long>((n + 1) / 2), s, n / s,
              n > 0 ? static_cast<double>(bytes) / n : 0.0);
  return 0;
}

int FleetQuery(const std::string& url, int64_t versions, int queries) {
  const auto t_open = std::chrono::steady_clock::now();
  auto store = fluxcal::pipeline::OpenStore(url, /*create=*/false);
  if (!store.ok()) {
    std::fprintf(stderr, "%s\n", std::string(store.status().message()).c_str());
    return 1;
  }
  const double open_s = Seconds(t_open);
  // Version k of the ingest is version k % 2 + 1 of motor k / 2.
  std::mt19937_64 rng(7);
  std::uniform_int_distribution<int64_t> pick(0, std::max<int64_t>(versions, 1) - 1);
  std::vector<double> ms;
  for (int q = 0; q < queries; ++q) {
    const int64_t k = pick(rng);
    const std::string serial = Serial(k / 2);
    const int version = static_cast<int>(k % 2) + 1;
    const auto t0 = std::chrono::steady_clock::now();
    auto r = fluxcal::pipeline::QueryFlux(**store, serial, version, {{-20.0, 10.0}});
    ms.push_back(1e3 * Seconds(t0));
    if (!r.ok()) {
      std::fprintf(stderr, "%s v%d: %s\n", serial.c_str(), version, std::string(r.status().message()).c_str());
      return 1;
    }
  }
  std::sort(ms.begin(), ms.end());
  auto at = [&](double f) { return ms[std::min(ms.size() - 1, static_cast<size_t>(f * ms.size()))]; };
  std::printf("fleet-query %s: %d QueryFlux of random versions among %lld: p50 %.2f ms, p99 %.2f ms, max %.2f ms "
              "(open %.2f s)\n",
              url.c_str(), queries, static_cast<long long>(versions), at(0.5), at(0.99), ms.back(), open_s);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc >= 5 && std::strcmp(argv[1], "--fleet-ingest") == 0) {
    return FleetIngest(argv[2], std::atoll(argv[3]), std::atof(argv[4]), argc >= 6 ? std::atoll(argv[5]) : 0);
  }
  if (argc >= 5 && std::strcmp(argv[1], "--fleet-query") == 0) {
    return FleetQuery(argv[2], std::atoll(argv[3]), std::atoi(argv[4]));
  }
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
