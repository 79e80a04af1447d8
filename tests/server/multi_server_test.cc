// Several stateless servers, one PostgreSQL: 3 real `fluxcal serve`
// processes on one database started by the test, 64 station clients each
// (ingest a run, ingest again, fit a serial that clients of every server
// fit at the same time). One server is killed with SIGKILL mid-run; its
// clients retry on the next server. Afterwards: 0 failed operations, every
// acknowledged run intact with all its points, calibration versions per
// serial unique and gap-free (1..n), every acknowledged version stored.
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <map>
#include <mutex>
#include <set>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "fluxcal/v1/calibration.grpc.pb.h"
#include "gtest/gtest.h"
#include "simulation/twin.h"
#include "tests/support/pg_cluster.h"

namespace fluxcal::server {
namespace {

constexpr int kServers = 3, kClientsPerServer = 64, kSharedSerials = 8;

v1::IngestHfResultsRequest StationRun(const std::string& serial, double scale) {
  sim::AnalyticMotor m{sim::MotorParams{}};
  v1::IngestHfResultsRequest r;
  r.set_serial(serial);
  r.set_station_id("st");
  r.mutable_motor()->set_pole_pairs(4);
  r.mutable_motor()->set_rs_ohm(0.011);
  r.mutable_motor()->set_psi_pm_wb(0.0114);
  for (int a = 0; a < 6; ++a) {
    for (int b = 0; b < 6; ++b) {
      auto* p = r.add_points();
      p->set_point_id("p" + std::to_string(6 * a + b));
      p->set_id_a(-100 + 20 * a);
      p->set_iq_a(20 * b);
      const auto L = m.Inductance(p->id_a(), p->iq_a());
      p->set_ld_h(scale * L.ldd_h); p->set_lq_h(scale * L.lqq_h); p->set_ldq_h(L.ldq_h);
      p->set_ld_h_std(1e-7); p->set_lq_h_std(1e-7); p->set_ldq_h_std(1e-7);
      p->set_reliable(true);
    }
  }
  return r;
}

bool Retryable(const grpc::Status& s) {
  switch (s.error_code()) {
    case grpc::StatusCode::UNAVAILABLE: case grpc::StatusCode::CANCELLED: case grpc::StatusCode::UNKNOWN:
    case grpc::StatusCode::INTERNAL: case grpc::StatusCode::DEADLINE_EXCEEDED: case grpc::StatusCode::ABORTED:
      return true;
    default:
      return false;
  }
}

TEST(MultiServer, ThreeServersSixtyFourClientsEachWithKillNine) {
  std::string why;
  fluxcal::testing::PgCluster* pg = fluxcal::testing::SharedPgCluster(&why);
  FLUXCAL_PG_OR_SKIP(pg, why, "PostgreSQL multi-server test skipped");
  ASSERT_TRUE(pg->CreateDatabase("fleet"));
  const std::string url = pg->Url("fleet");
  std::vector<pid_t> pids;
  std::vector<std::string> addrs;
  for (int s = 0; s < kServers; ++s) {
    const int port = fluxcal::testing::PgCluster::FreePort();
    addrs.push_back("127.0.0.1:" + std::to_string(port));
    const pid_t child = fork();
    if (child == 0) {
      // Open mode: the 64 stations of a server are one identity ("local")
      // here, so its limit of open calls is theirs together.
      execl(FLUXCAL_BINARY, FLUXCAL_BINARY, "serve", "--db", url.c_str(), "--listen", addrs.back().c_str(),
            "--max-streams-per-identity", "256", nullptr);
      _exit(127);
    }
    pids.push_back(child);
  }
  std::vector<std::shared_ptr<grpc::Channel>> channels;
  for (const auto& a : addrs) channels.push_back(grpc::CreateChannel(a, grpc::InsecureChannelCredentials()));
  for (int s = 0; s < kServers; ++s) {
    auto stub = v1::CalibrationService::NewStub(channels[s]);
    bool up = false;
    for (int k = 0; k < 150 && !up; ++k) {
      grpc::ClientContext c;
      c.set_deadline(std::chrono::system_clock::now() + std::chrono::milliseconds(200));
      v1::ListMotorsResponse lr;
      up = stub->ListMotors(&c, v1::ListMotorsRequest(), &lr).ok();
      if (!up) std::this_thread::sleep_for(std::chrono::milliseconds(100));
    }
    ASSERT_TRUE(up) << "server " << s << " did not come up on " << addrs[s];
  }
  // The shared serials exist before the clients start fitting them.
  for (int k = 0; k < kSharedSerials; ++k) {
    auto stub = v1::CalibrationService::NewStub(channels[k % kServers]);
    grpc::ClientContext ctx;
    v1::IngestHfResultsResponse r;
    auto w = stub->IngestHfResults(&ctx, &r);
    w->Write(StationRun("SHARED-" + std::to_string(k), 1.0));
    w->WritesDone();
    ASSERT_TRUE(w->Finish().ok());
  }

  constexpr int kClients = kServers * kClientsPerServer, kOpsPerClient = 3;
  std::atomic<int> done{0}, failures{0}, retries{0};
  std::mutex mu;
  std::vector<std::pair<int64_t, int>> acked_runs;            // run id, points
  std::vector<std::pair<std::string, int>> acked_versions;    // serial, version
  std::vector<std::string> failure_messages;
  std::atomic<bool> killed{false};
  std::thread killer([&] {
    while (done.load() < kClients * kOpsPerClient / 3) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    kill(pids[0], SIGKILL);
    killed = true;
  });
  std::vector<std::thread> clients;
  for (int c = 0; c < kClients; ++c) {
    clients.emplace_back([&, c] {
      int server = c % kServers;
      auto call = [&](const std::function<grpc::Status(v1::CalibrationService::Stub*)>& op) {
        for (int attempt = 0; attempt < 8; ++attempt) {
          auto stub = v1::CalibrationService::NewStub(channels[server]);
          const grpc::Status s = op(stub.get());
          if (s.ok()) return true;
          if (!Retryable(s)) {
            std::lock_guard<std::mutex> l(mu);
            failure_messages.push_back(s.error_message());
            return false;
          }
          ++retries;
          server = (server + 1) % kServers;   // the station's fail-over list
          std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
        return false;
      };
      const std::string own = "ST-" + std::to_string(c);
      for (int round = 0; round < 2; ++round) {
        v1::IngestHfResultsResponse r;
        const bool ok = call([&](v1::CalibrationService::Stub* stub) {
          grpc::ClientContext ctx;
          ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
          r.Clear();
          auto w = stub->IngestHfResults(&ctx, &r);
          w->Write(StationRun(own, 1.0 + 0.001 * round));
          w->WritesDone();
          return w->Finish();
        });
        if (ok) {
          std::lock_guard<std::mutex> l(mu);
          acked_runs.push_back({r.run_id(), r.accepted()});
        } else {
          ++failures;
        }
        ++done;
      }
      const std::string shared = "SHARED-" + std::to_string(c % kSharedSerials);
      v1::FitResponse fr;
      const bool ok = call([&](v1::CalibrationService::Stub* stub) {
        grpc::ClientContext ctx;
        ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
        v1::FitRequest f;
        f.set_serial(shared);
        f.set_model("analytic");
        return stub->Fit(&ctx, f, &fr);
      });
      if (ok) {
        std::lock_guard<std::mutex> l(mu);
        acked_versions.push_back({shared, fr.calibration().version()});
      } else {
        ++failures;
      }
      ++done;
    });
  }
  for (auto& t : clients) t.join();
  killer.join();
  EXPECT_TRUE(killed.load());
  for (pid_t p : pids) {
    kill(p, SIGKILL);
    waitpid(p, nullptr, 0);
  }
  EXPECT_EQ(failures.load(), 0) << (failure_messages.empty() ? "" : failure_messages[0]);
  EXPECT_GT(retries.load(), 0) << "the kill should have made some clients fail over";
  // Every acknowledged run is stored with all its points.
  ASSERT_EQ(acked_runs.size(), static_cast<size_t>(2 * kClients));
  std::string ids;
  for (const auto& [id, n] : acked_runs) {
    EXPECT_EQ(n, 36);
    ids += (ids.empty() ? "" : ",") + std::to_string(id);
  }
  EXPECT_EQ(pg->Scalar("fleet", "SELECT COUNT(*) FROM runs WHERE run_id IN (" + ids + ")"),
            std::to_string(acked_runs.size()));
  EXPECT_EQ(pg->Scalar("fleet", "SELECT COUNT(*) FROM hf_points WHERE run_id IN (" + ids + ")"),
            std::to_string(36 * acked_runs.size()));
  // No half-stored run anywhere (a killed stream leaves nothing).
  EXPECT_EQ(pg->Scalar("fleet", "SELECT COUNT(*) FROM runs r WHERE (SELECT COUNT(*) FROM hf_points p "
                                "WHERE p.run_id = r.run_id) <> 36"),
            "0");
  // Versions: no acknowledged duplicate, each stored, 1..n without gaps.
  std::set<std::pair<std::string, int>> unique(acked_versions.begin(), acked_versions.end());
  EXPECT_EQ(unique.size(), acked_versions.size()) << "a version was acknowledged twice";
  EXPECT_EQ(acked_versions.size(), static_cast<size_t>(kClients));
  EXPECT_EQ(pg->Scalar("fleet", "SELECT COUNT(*) FROM (SELECT serial FROM calibrations GROUP BY serial "
                                "HAVING MAX(version) <> COUNT(*) OR MIN(version) <> 1) g"),
            "0");
  const std::string stored = pg->Scalar("fleet", "SELECT COUNT(*) FROM calibrations");
  EXPECT_GE(std::stoi(stored), kClients);   // a fit whose reply was lost to the kill may be stored once more
  for (const auto& [serial, v] : unique) {
    EXPECT_EQ(pg->Scalar("fleet", "SELECT COUNT(*) FROM calibrations WHERE serial = '" + serial +
                                      "' AND version = " + std::to_string(v)),
              "1");
  }
}

}  // namespace
}  // namespace fluxcal::server
