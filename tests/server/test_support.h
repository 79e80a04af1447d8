// What the service's tests build their requests from: the paper's grid of
// HF points from the twin's analytic motor, the smallest run the service
// takes, a short simulated recording set as IngestRecording takes it, and
// the streams that send them.
#ifndef FLUXCAL_TESTS_SERVER_TEST_SUPPORT_H_
#define FLUXCAL_TESTS_SERVER_TEST_SUPPORT_H_

#include <algorithm>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "fluxcal/v1/calibration.grpc.pb.h"
#include "gtest/gtest.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "server/service.h"
#include "storage/store.h"
#include "simulation/twin.h"

namespace fluxcal::server::test_support {

// A service on the store at url, served on a free loopback port (*port)
// without an authorizer: fails naming what did not open or start.
inline ::testing::AssertionResult ServeStore(const std::string& url, std::unique_ptr<storage::Store>* store,
                                             std::unique_ptr<CalibrationServiceImpl>* service,
                                             std::unique_ptr<grpc::Server>* server, int* port) {
  auto s = storage::Store::Open(url);
  if (!s.ok()) return ::testing::AssertionFailure() << url << ": " << s.status();
  *store = std::move(*s);
  *service = std::make_unique<CalibrationServiceImpl>(store->get());
  *port = 0;
  *server = StartServer(service->get(), "127.0.0.1:0", port);
  if (*server == nullptr || *port <= 0) return ::testing::AssertionFailure() << "the server did not start";
  return ::testing::AssertionSuccess();
}

// 36 points of the paper's grid (id -100..0 A, iq 0..100 A in 20 A steps)
// from the twin's analytic motor; scale multiplies Ldd and Lqq.
inline std::vector<v1::HfPoint> TwinGridPoints(double scale = 1.0) {
  sim::MotorParams mp;
  sim::AnalyticMotor m(mp);
  std::vector<v1::HfPoint> out;
  for (int a = 0; a < 6; ++a) {
    for (int b = 0; b < 6; ++b) {
      v1::HfPoint p;
      p.set_point_id("p" + std::to_string(6 * a + b));
      p.set_id_a(-100 + 20 * a);
      p.set_iq_a(20 * b);
      const auto L = m.Inductance(p.id_a(), p.iq_a());
      p.set_ld_h(scale * L.ldd_h); p.set_lq_h(scale * L.lqq_h); p.set_ldq_h(L.ldq_h);
      p.set_ld_h_std(1e-7); p.set_lq_h_std(1e-7); p.set_ldq_h_std(1e-7);
      p.set_temperature_c(25); p.set_reliable(true);
      out.push_back(p);
    }
  }
  return out;
}

// The files of the twin's recording set for cfg, record_s seconds a point,
// as IngestRecording takes them (relative names, bytes as on disk); the
// set is written to scratch_dir and removed again.
inline io::RecordingFiles TwinSetFiles(const sim::TwinConfig& cfg, double record_s, const std::string& scratch_dir) {
  namespace fs = std::filesystem;
  sim::Plan plan = sim::DefaultPlan();
  plan.record_s = record_s;
  auto r = sim::Simulate(cfg, plan);
  EXPECT_TRUE(r.ok());
  fs::remove_all(scratch_dir);
  EXPECT_TRUE(io::WriteRecordingSet(scratch_dir, r->set).ok());
  io::RecordingFiles files;
  for (const auto& e : fs::recursive_directory_iterator(scratch_dir)) {
    if (!e.is_regular_file()) continue;
    files[fs::relative(e.path(), scratch_dir).generic_string()] = *io::ReadFileToString(e.path().string());
  }
  fs::remove_all(scratch_dir);
  return files;
}
// The same for the default twin named serial.
inline io::RecordingFiles TwinSetFiles(const std::string& serial, double record_s, const std::string& scratch_dir) {
  sim::TwinConfig cfg;
  cfg.serial = serial;
  return TwinSetFiles(cfg, record_s, scratch_dir);
}

// One IngestRecording stream: the (name, bytes) of files in their order, a
// chunk each (with chunk_bytes > 0: chunks of at most that many bytes), the
// first with serial and station.
template <class Files>
grpc::Status UploadRecording(v1::CalibrationService::Stub* stub, const std::string& serial,
                             const std::string& station, const Files& files, v1::IngestRecordingResponse* resp,
                             size_t chunk_bytes = 0) {
  grpc::ClientContext ctx;
  auto w = stub->IngestRecording(&ctx, resp);
  bool first = true;
  for (const auto& [name, data] : files) {
    const size_t step = chunk_bytes > 0 ? chunk_bytes : std::max<size_t>(data.size(), 1);
    for (size_t off = 0; off == 0 || off < data.size(); off += step) {
      v1::RecordingChunk c;
      if (first) {
        c.set_serial(serial);
        c.set_station_id(station);
        first = false;
      }
      c.set_path(name);
      c.set_data(data.substr(off, step));
      if (!w->Write(c)) {
        w->WritesDone();
        return w->Finish();
      }
    }
  }
  w->WritesDone();
  return w->Finish();
}

// The smallest run the service takes: six distinct operating points.
inline std::vector<v1::HfPoint> SmallGrid() {
  std::vector<v1::HfPoint> out;
  for (int k = 0; k < 6; ++k) {
    v1::HfPoint p;
    p.set_point_id("p" + std::to_string(k));
    p.set_id_a(-20.0 * (k % 3)); p.set_iq_a(40.0 * (k / 3)); p.set_ld_h(1e-4); p.set_lq_h(2e-4);
    p.set_temperature_c(25); p.set_reliable(true);
    out.push_back(p);
  }
  return out;
}

// One IngestHfResults stream on ctx: SmallGrid for serial (4 pole pairs),
// with a station id when one is given.
inline grpc::Status IngestSmallGrid(v1::CalibrationService::Stub* stub, grpc::ClientContext* ctx,
                                    const std::string& serial, const std::string& station = "") {
  v1::IngestHfResultsResponse r;
  auto w = stub->IngestHfResults(ctx, &r);
  v1::IngestHfResultsRequest m;
  m.set_serial(serial);
  if (!station.empty()) m.set_station_id(station);
  m.mutable_motor()->set_pole_pairs(4);
  for (const auto& p : SmallGrid()) *m.add_points() = p;
  w->Write(m);
  w->WritesDone();
  return w->Finish();
}

}  // namespace fluxcal::server::test_support

#endif  // FLUXCAL_TESTS_SERVER_TEST_SUPPORT_H_
