// Load client: HF-result ingest over loopback into SQLite with durable
// commits (8 concurrent station streams), and QueryFlux latency; each in
// plaintext and with TLS plus a bearer token checked on every call (the
// certificate made at start by Debian's openssl). Run:
//   ./build/bench/server_bench --benchmark_min_time=1
#include <algorithm>
#include <cstdlib>
#include <chrono>
#include <filesystem>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "benchmark/benchmark.h"
#include <grpcpp/support/client_interceptor.h>

#include "io/csv.h"
#include "server/auth.h"
#include "server/service.h"
#include "storage/store.h"
#include "tables/sha256.h"

namespace {

// Adds the bearer token to every call.
class Bearer final : public grpc::experimental::Interceptor {
 public:
  explicit Bearer(std::string h) : h_(std::move(h)) {}
  void Intercept(grpc::experimental::InterceptorBatchMethods* m) override {
    if (m->QueryInterceptionHookPoint(grpc::experimental::InterceptionHookPoints::PRE_SEND_INITIAL_METADATA)) {
      m->GetSendInitialMetadata()->insert({"authorization", h_});
    }
    m->Proceed();
  }
  std::string h_;
};
class BearerFactory final : public grpc::experimental::ClientInterceptorFactoryInterface {
 public:
  explicit BearerFactory(std::string h) : h_(std::move(h)) {}
  grpc::experimental::Interceptor* CreateClientInterceptor(grpc::experimental::ClientRpcInfo*) override {
    return new Bearer(h_);
  }
  std::string h_;
};

struct Fixture {
  std::string db;
  std::unique_ptr<fluxcal::storage::Store> store;
  std::unique_ptr<fluxcal::server::CalibrationServiceImpl> service;
  std::unique_ptr<fluxcal::server::Authorizer> auth;
  std::unique_ptr<grpc::Server> server;
  std::shared_ptr<grpc::Channel> channel;
  explicit Fixture(bool tls) {
    namespace fs = std::filesystem;
    const fs::path tmp = fs::temp_directory_path();
    db = (tmp / (tls ? "fluxcal_server_bench_tls.db" : "fluxcal_server_bench.db")).string();
    for (auto s : {"", "-wal", "-shm"}) std::filesystem::remove(db + s);
    store = std::move(*fluxcal::storage::Store::Open(db));
    service = std::make_unique<fluxcal::server::CalibrationServiceImpl>(store.get());
    int port = 0;
    if (!tls) {
      server = fluxcal::server::StartServer(service.get(), "127.0.0.1:0", &port);
      channel = grpc::CreateChannel("127.0.0.1:" + std::to_string(port), grpc::InsecureChannelCredentials());
      return;
    }
    const std::string dir = (tmp / "fluxcal_server_bench_pki").string();
    const std::string cmd =
        "mkdir -p " + dir + " && cd " + dir +
        " && openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout s.key -out s.pem"
        " -days 1 -subj /CN=localhost -addext subjectAltName=IP:127.0.0.1 2>/dev/null";
    if (std::system(cmd.c_str()) != 0) std::abort();
    const std::string token = *fluxcal::server::NewToken();
    fluxcal::server::Keys keys;
    keys.entries.push_back({"station-bench", fluxcal::server::Role::kStation, fluxcal::tables::Sha256Hex(token), ""});
    keys.entries.push_back({"engineer-bench", fluxcal::server::Role::kEngineer,
                            fluxcal::tables::Sha256Hex(token + "e"), ""});
    auth = std::make_unique<fluxcal::server::Authorizer>(keys);
    service->set_authorizer(auth.get());
    fluxcal::server::ServerOptions opt;
    opt.tls_cert_pem = *fluxcal::io::ReadFileToString(dir + "/s.pem");
    opt.tls_key_pem = *fluxcal::io::ReadFileToString(dir + "/s.key");
    opt.authorizer = auth.get();
    server = fluxcal::server::StartServer(service.get(), "127.0.0.1:0", &port, opt);
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = opt.tls_cert_pem;
    // The station token can ingest and fit; QueryFlux also allows stations.
    std::vector<std::unique_ptr<grpc::experimental::ClientInterceptorFactoryInterface>> f;
    f.push_back(std::make_unique<BearerFactory>("Bearer " + token));
    channel = grpc::experimental::CreateCustomChannelWithInterceptors(
        "127.0.0.1:" + std::to_string(port), grpc::SslCredentials(ssl), grpc::ChannelArguments(), std::move(f));
  }
};

Fixture& F(bool tls) {
  static Fixture* plain = new Fixture(false);
  static Fixture* secure = nullptr;
  if (!tls) return *plain;
  if (secure == nullptr) secure = new Fixture(true);
  return *secure;
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
  const bool tls = state.range(1) != 0;
  auto stub = fluxcal::v1::CalibrationService::NewStub(F(tls).channel);
  int64_t total = 0, iter = 0;
  for (auto _ : state) {
    std::vector<std::thread> th;
    for (int s = 0; s < 8; ++s) {
      th.emplace_back([&, s] {
        grpc::ClientContext ctx;
        fluxcal::v1::IngestHfResultsResponse r;
        auto w = stub->IngestHfResults(&ctx, &r);
        fluxcal::v1::IngestHfResultsRequest first;
        first.set_serial(std::string(tls ? "IPM-TLS-" : "IPM-LOAD-") + std::to_string(iter) + "-" + std::to_string(s));
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
// Args: points per stream, TLS + token (0/1).
BENCHMARK(BM_Ingest8Streams)
    ->Args({36, 0})->Args({10000, 0})->Args({36, 1})->Args({10000, 1})
    ->UseRealTime()->Unit(benchmark::kMillisecond);

// QueryFlux of one point against a stored calibration; p50/p99 latency.
void BM_QueryFluxLatency(benchmark::State& state) {
  auto stub = fluxcal::v1::CalibrationService::NewStub(F(state.range(0) != 0).channel);
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
// Arg: TLS + token (0/1).
BENCHMARK(BM_QueryFluxLatency)->Arg(0)->Arg(1)->UseRealTime()->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
