// Load client: HF-result ingest over loopback (8 concurrent station streams,
// one durable commit per stream) and QueryFlux latency, on SQLite (one
// server) beside PostgreSQL with 1 and 3 stateless servers sharing one
// database (a throw-away cluster started here, fsync on), and SQLite with
// TLS plus a bearer token checked on every call (backend 2; an ECDSA P-256
// certificate made by Debian's openssl at start). Run:
//   ./build/bench/server_bench --benchmark_min_time=1
#include <algorithm>
#include <cstdlib>
#include <chrono>
#include <filesystem>
#include <map>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "benchmark/benchmark.h"
#include "io/csv.h"
#include "server/auth.h"
#include "server/bearer.h"
#include "server/service.h"
#include "storage/store.h"
#include "io/sha256.h"
#include "tests/support/pg_cluster.h"

namespace {

// N servers (each its own store object, i.e. its own connections) on one
// database; the channels a load balancer would spread clients over.
struct Fixture {
  std::vector<std::unique_ptr<fluxcal::storage::Store>> stores;
  std::vector<std::unique_ptr<fluxcal::server::CalibrationServiceImpl>> services;
  std::vector<std::unique_ptr<grpc::Server>> servers;
  std::vector<std::shared_ptr<grpc::Channel>> channels;
  std::unique_ptr<fluxcal::server::Authorizer> auth;
  std::string error;
  Fixture(const std::string& url, int n, bool tls = false) {
    fluxcal::server::ServerOptions opt;
    std::string token;
    if (tls) {
      const std::string dir = (std::filesystem::temp_directory_path() / "fluxcal_server_bench_pki").string();
      const std::string cmd =
          "mkdir -p " + dir + " && cd " + dir +
          " && openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout s.key -out s.pem"
          " -days 1 -subj /CN=localhost -addext subjectAltName=IP:127.0.0.1 2>/dev/null";
      if (std::system(cmd.c_str()) != 0) { error = "openssl could not make a certificate"; return; }
      opt.tls_cert_pem = *fluxcal::io::ReadFileToString(dir + "/s.pem");
      opt.tls_key_pem = *fluxcal::io::ReadFileToString(dir + "/s.key");
      token = *fluxcal::server::NewToken();
      fluxcal::server::Keys keys;
      keys.entries.push_back({"station-bench", fluxcal::server::Role::kStation, fluxcal::io::Sha256Hex(token), ""});
      auth = std::make_unique<fluxcal::server::Authorizer>(keys);
      opt.authorizer = auth.get();
    }
    for (int k = 0; k < n; ++k) {
      auto s = fluxcal::storage::Store::Open(url);
      if (!s.ok()) { error = std::string(s.status().message()); return; }
      stores.push_back(std::move(*s));
      services.push_back(std::make_unique<fluxcal::server::CalibrationServiceImpl>(stores.back().get()));
      services.back()->set_authorizer(auth.get());
      int port = 0;
      servers.push_back(fluxcal::server::StartServer(services.back().get(), "127.0.0.1:0", &port, opt));
      const std::string addr = "127.0.0.1:" + std::to_string(port);
      if (!tls) {
        channels.push_back(grpc::CreateChannel(addr, grpc::InsecureChannelCredentials()));
        continue;
      }
      grpc::SslCredentialsOptions ssl;
      ssl.pem_root_certs = opt.tls_cert_pem;
      channels.push_back(fluxcal::server::BearerChannel(addr, grpc::SslCredentials(ssl), token));
    }
  }
};

fluxcal::testing::PgCluster* Pg(std::string* why) {
  static std::string reason;
  static std::unique_ptr<fluxcal::testing::PgCluster> c = fluxcal::testing::PgCluster::Start(&reason, /*durable=*/true);
  *why = reason;
  return c.get();
}

// backend 0: SQLite file; 1: PostgreSQL; 2: SQLite file with TLS + token. One database per (backend, servers).
Fixture* F(int backend, int n, std::string* why) {
  static std::map<std::pair<int, int>, Fixture*> all;
  auto& f = all[{backend, n}];
  if (f) return f;
  if (backend == 0 || backend == 2) {
    const std::string db =
        (std::filesystem::temp_directory_path() / (backend == 0 ? "fluxcal_server_bench.db" : "fluxcal_server_bench_tls.db"))
            .string();
    for (auto s : {"", "-wal", "-shm"}) std::filesystem::remove(db + s);
    f = new Fixture(db, n, backend == 2);
  } else {
    auto* pg = Pg(why);
    if (!pg) return nullptr;
    const std::string name = "bench_" + std::to_string(n);
    pg->CreateDatabase(name);
    f = new Fixture(pg->Url(name), n);
  }
  if (!f->error.empty()) *why = f->error;
  return f->error.empty() ? f : nullptr;
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

// Each iteration: 8 station streams per server, each `points` points (sent
// in messages of 500), one durable transaction per stream. Args: backend,
// servers, points.
void BM_Ingest(benchmark::State& state) {
  const int backend = static_cast<int>(state.range(0)), n = static_cast<int>(state.range(1));
  const int points = static_cast<int>(state.range(2));
  std::string why;
  Fixture* f = F(backend, n, &why);
  if (!f) { state.SkipWithError(why.c_str()); return; }
  std::vector<std::unique_ptr<fluxcal::v1::CalibrationService::Stub>> stubs;
  for (auto& c : f->channels) stubs.push_back(fluxcal::v1::CalibrationService::NewStub(c));
  static int64_t iter = 0;
  int64_t total = 0;
  for (auto _ : state) {
    std::vector<std::thread> th;
    const int streams = 8 * n;
    for (int s = 0; s < streams; ++s) {
      th.emplace_back([&, s, it = iter] {
        grpc::ClientContext ctx;
        fluxcal::v1::IngestHfResultsResponse r;
        auto w = stubs[s % n]->IngestHfResults(&ctx, &r);
        fluxcal::v1::IngestHfResultsRequest first;
        first.set_serial("IPM-LOAD-" + std::to_string(n) + "-" + std::to_string(it) + "-" + std::to_string(s));
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
    total += static_cast<int64_t>(streams) * points;
    ++iter;
  }
  state.counters["points_per_s"] = benchmark::Counter(static_cast<double>(total), benchmark::Counter::kIsRate);
  state.counters["points_per_s_per_server"] =
      benchmark::Counter(static_cast<double>(total) / n, benchmark::Counter::kIsRate);
}
BENCHMARK(BM_Ingest)
    ->ArgNames({"backend", "servers", "points"})
    ->Args({0, 1, 36})->Args({0, 1, 10000})
    ->Args({1, 1, 36})->Args({1, 1, 10000})
    ->Args({1, 3, 36})->Args({1, 3, 10000})
    ->Args({2, 1, 36})->Args({2, 1, 10000})
    ->UseRealTime()->Unit(benchmark::kMillisecond);

// QueryFlux of one point against a stored calibration from 4 client threads
// per server, spread over the servers; p50/p99 latency. Args: backend, servers.
void BM_QueryFlux(benchmark::State& state) {
  const int backend = static_cast<int>(state.range(0)), n = static_cast<int>(state.range(1));
  std::string why;
  Fixture* f = F(backend, n, &why);
  if (!f) { state.SkipWithError(why.c_str()); return; }
  const std::string serial = "IPM-QUERY-" + std::to_string(n);
  {
    auto stub = fluxcal::v1::CalibrationService::NewStub(f->channels[0]);
    grpc::ClientContext ctx;
    fluxcal::v1::IngestHfResultsResponse r;
    auto w = stub->IngestHfResults(&ctx, &r);
    fluxcal::v1::IngestHfResultsRequest first = Batch(36, 0);
    first.set_serial(serial);
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
    fluxcal::v1::FitRequest fq;
    fq.set_serial(serial);
    fluxcal::v1::FitResponse fr;
    stub->Fit(&fc, fq, &fr);
  }
  std::vector<double> lat;
  int64_t calls = 0;
  const int threads = 4 * n;
  for (auto _ : state) {
    // One iteration: each thread makes 50 calls.
    std::vector<std::vector<double>> per(threads);
    std::vector<std::thread> th;
    for (int t = 0; t < threads; ++t) {
      th.emplace_back([&, t] {
        auto stub = fluxcal::v1::CalibrationService::NewStub(f->channels[t % n]);
        for (int k = 0; k < 50; ++k) {
          grpc::ClientContext ctx;
          fluxcal::v1::QueryFluxRequest q;
          q.set_serial(serial);
          auto* p = q.add_points();
          p->set_id_a(-20);
          p->set_iq_a(40);
          fluxcal::v1::QueryFluxResponse r;
          const auto t0 = std::chrono::steady_clock::now();
          if (!stub->QueryFlux(&ctx, q, &r).ok()) std::abort();
          per[t].push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count());
        }
      });
    }
    for (auto& x : th) x.join();
    for (auto& v : per) lat.insert(lat.end(), v.begin(), v.end());
    calls += 50 * threads;
  }
  std::sort(lat.begin(), lat.end());
  state.counters["p50_ms"] = lat[lat.size() / 2];
  state.counters["p99_ms"] = lat[std::min(lat.size() - 1, lat.size() * 99 / 100)];
  state.counters["queries_per_s"] = benchmark::Counter(static_cast<double>(calls), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_QueryFlux)
    ->ArgNames({"backend", "servers"})
    ->Args({0, 1})->Args({1, 1})->Args({1, 3})->Args({2, 1})
    ->UseRealTime()->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
