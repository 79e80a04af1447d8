// Reading a 36-point recording set of 1000 rows each. Run:
//   ./build/bench/io_bench --benchmark_min_time=1
#include <cmath>
#include <filesystem>

#include "benchmark/benchmark.h"
#include "io/recording_set.h"

namespace {

std::string MakeSet() {
  namespace fs = std::filesystem;
  const std::string dir = (fs::temp_directory_path() / "fluxcal_io_bench_set").string();
  fluxcal::io::RecordingSet s;
  auto& m = s.manifest;
  m.serial = "IPM-BENCH-1";
  m.motor.pole_pairs = 4;
  m.drive.f_sample_hz = 10000;
  m.drive.udc_v = 50;
  m.injection = fluxcal::io::InjectionInfo{"rotating", 5, 500};
  for (int p = 0; p < 36; ++p) {
    fluxcal::io::PointSpec ps;
    ps.id = "p" + std::to_string(p);
    ps.file = "points/" + ps.id + ".csv";
    m.points.push_back(ps);
    fluxcal::io::Waveform w;
    for (int k = 0; k < 1000; ++k) {
      const double t = k * 1e-4;
      w.t_s.push_back(t);
      w.ia_a.push_back(50 * std::cos(3141.6 * t));
      w.ib_a.push_back(50 * std::cos(3141.6 * t - 2.0944));
      w.ic_a.push_back(50 * std::cos(3141.6 * t + 2.0944));
      w.theta_e_rad.push_back(0.5);
      w.ualpha_ref_v.push_back(5 * std::cos(3141.6 * t));
      w.ubeta_ref_v.push_back(5 * std::sin(3141.6 * t));
      w.udc_v.push_back(50.0);
    }
    s.waveforms.push_back(w);
  }
  (void)fluxcal::io::WriteRecordingSet(dir, s);
  return dir;
}

void BM_Read36PointSet(benchmark::State& state) {
  static const std::string dir = MakeSet();
  for (auto _ : state) {
    auto r = fluxcal::io::ReadRecordingSet(dir);
    if (!r.ok()) state.SkipWithError("read failed");
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK(BM_Read36PointSet)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
