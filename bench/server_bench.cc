// Load client: HF-result ingest over loopback into SQLite with durable
// commits (8 concurrent station streams), and QueryFlux latency. Run:
//   ./build/bench/server_bench --benchmark_min_time=1
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "benchmark/benchmark.h"
#include "server/service.h"
#include "storage/store.h"

namespace {

struct Fixture {
  std::string db;
  std::unique_ptr<fluxcal::storage::Store> store;
  std::unique_ptr<fluxcal::server::CalibrationServiceImpl> service;
  std::unique_ptr<grpc::Server> server;
  std::shared_ptr<grpc::Channel> channel;
  Fixture() {
    db = (std::filesystem::temp_directory_path() / "fluxcal_server_bench.db").string();
    for (auto s : {"", "-wal", "-shm"}) std::filesystem::remove(db + s);
    store = std::move(*fluxcal::storage::Store::Open(db));
    service = std::make_unique<fluxcal::server::CalibrationServiceImpl>(store.get());
    int port = 0;
    server = fluxcal::server::StartServer(service.get(), "127.0.0.1:0", &port);
    channel = grpc::CreateChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials());
  }
};

Fixture& F() {
  static Fixture* f = new Fixture;
  return *f;
}

fluxcal::v1::IngestHfResultsRequest Batch(int n, int offset) {
  fluxcal::v1::IngestHfResultsRequest m;
  for (int k = 0; k < n; ++k) {
    auto* p = m.add_points();
    p->set_point_id("p" + std::to_string(offset + k));
    p->set_id_a(-100 + (k % 6) * 20);
    p->set_iq_a((k / 6 % 6) * 20);
    p->set_ld_h(1.8e-4);
    p->set_lq_h(3.6e-4);
    p->set_ldq_h(0.0);
    p->set_ld_h_std(1e-7);
    p->set_lq_h_std(1e-7);
    p->set_temperature_c(25);
    p->set_reliable(true);
  }
  return m;
}

// Each iteration: 8 threads, each one stream of `points` points (sent in
// messages of 500), one durable transaction per stream.
void BM_Ingest8Streams(benchmark::State& state) {
  const int points = static_cast<int>(state.range(0));
  auto stub = fluxcal::v1::CalibrationService::NewStub(F().channel);
  int64_t total = 0, iter = 0;
  for (auto _ : state) {
    std::vector<std::thread> th;
    for (int s = 0; s < 8; ++s) {
      th.emplace_back([&, s] {
        grpc::ClientContext ctx;
        fluxcal::v1::IngestHfResultsResponse r;
        auto w = stub->IngestHfResults(&ctx, &r);
        fluxcal::v1::IngestHfResultsRequest first;
        first.set_serial("IPM-LOAD-" + std::to_string(iter) + "-" + std::to_string(s));
        first.mutable_motor()->set_pole_pairs(4);
        first.mutable_motor()->set_rs_ohm(0.011);
        first.mutable_motor()->set_psi_pm_wb(0.0114);
        w->Write(first);
        for (int k = 0; k < points; k += 500) w->Write(Batch(std::min(500, points - k), k));
        w->WritesDone();
        if (!w->Finish().ok()) std::abort();
      });
    }
    for (auto& t : th) t.join();
    total += 8LL * points;
    ++iter;
  }
  state.counters["points_per_s"] = benchmark::Counter(static_cast<double>(total), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Ingest8Streams)->Arg(36)->Arg(10000)->UseRealTime()->Unit(benchmark::kMillisecond);

// QueryFlux of one point against a stored calibration; p50/p99 latency.
void BM_QueryFluxLatency(benchmark::State& state) {
  auto stub = fluxcal::v1::CalibrationService::NewStub(F().channel);
  {
    grpc::ClientContext ctx;
    fluxcal::v1::IngestHfResultsResponse r;
    auto w = stub->IngestHfResults(&ctx, &r);
    fluxcal::v1::IngestHfResultsRequest first = Batch(36, 0);
    first.set_serial("IPM-QUERY-1");
    first.mutable_motor()->set_pole_pairs(4);
    first.mutable_motor()->set_psi_pm_wb(0.0114);
    for (int k = 0; k < 36; ++k) {
      auto* p = first.mutable_points(k);
      p->set_ld_h(1.8e-4 * (1 - 0.0005 * p->id_a() / 10));
      p->set_lq_h(3.7e-4 / (1 + p->iq_a() * p->iq_a() / 8e4));
    }
    w->Write(first);
    w->WritesDone();
    w->Finish();
    grpc::ClientContext fc;
    fluxcal::v1::FitRequest f;
    f.set_serial("IPM-QUERY-1");
    fluxcal::v1::FitResponse fr;
    stub->Fit(&fc, f, &fr);
  }
  std::vector<double> lat;
  for (auto _ : state) {
    grpc::ClientContext ctx;
    fluxcal::v1::QueryFluxRequest q;
    q.set_serial("IPM-QUERY-1");
    auto* p = q.add_points();
    p->set_id_a(-20);
    p->set_iq_a(40);
    fluxcal::v1::QueryFluxResponse r;
    const auto t0 = std::chrono::steady_clock::now();
    if (!stub->QueryFlux(&ctx, q, &r).ok()) state.SkipWithError("query failed");
    lat.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
  }
  std::sort(lat.begin(), lat.end());
  state.counters["p50_ms"] = lat[lat.size() / 2];
  state.counters["p99_ms"] = lat[std::min(lat.size() - 1, lat.size() * 99 / 100)];
}
BENCHMARK(BM_QueryFluxLatency)->UseRealTime()->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
