// Identity, roles and transport: the role matrix (each role x each RPC),
// anonymous and unknown callers, a station's identity on its runs, server
// policy on verdict tolerances, TLS and mutual TLS with a throwaway CA made
// by Debian's openssl, and `fluxcal serve` refusing unsafe listen setups.
#include <sqlite3.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <algorithm>
#include <map>

#include <google/protobuf/descriptor.pb.h>

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include "grpc/reflection/v1/reflection.grpc.pb.h"
#include "grpc/reflection/v1alpha/reflection.grpc.pb.h"
#include "gtest/gtest.h"
#include "io/csv.h"
#include "io/net.h"
#include "server/auth.h"
#include "server/bearer.h"
#include "tests/server/authorized_server.h"
#include "tests/server/test_support.h"
#include "io/sha256.h"
#include "pipeline/anchor.h"
#include "server/service.h"
#include "simulation/twin.h"
#include "storage/store.h"

namespace fluxcal::server {
namespace {

namespace fs = std::filesystem;

std::string TempPath(const std::string& name) {
  return (fs::temp_directory_path() / ("fluxcal_auth_" + std::to_string(::getpid()) + "_" + name)).string();
}

// A channel sending token with every call (what the CLI does with --token-file); "" sends none.
std::shared_ptr<grpc::Channel> Channel(const std::string& addr, std::shared_ptr<grpc::ChannelCredentials> creds,
                                       const std::string& token) {
  return BearerChannel(addr, creds, TokenOrNone(token));
}

using test_support::IngestSmallGrid;

// Calls `rpc` with a small request; the status is all that matters here.
grpc::Status Call(v1::CalibrationService::Stub* stub, Rpc rpc) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
  switch (rpc) {
    case Rpc::kIngestHfResults:
      return IngestSmallGrid(stub, &ctx, "IPM-AUTH-1");
    case Rpc::kIngestRecording: {
      v1::IngestRecordingResponse r;
      auto w = stub->IngestRecording(&ctx, &r);
      v1::RecordingChunk c;
      c.set_serial("IPM-AUTH-1");
      c.set_path("manifest.json");
      c.set_data("{}");
      w->Write(c);
      w->WritesDone();
      return w->Finish();
    }
    case Rpc::kFit: { v1::FitRequest q; q.set_serial("IPM-AUTH-1"); v1::FitResponse r; return stub->Fit(&ctx, q, &r); }
    case Rpc::kGetCalibration: {
      v1::GetCalibrationRequest q; q.set_serial("IPM-AUTH-1"); v1::CalibrationRecord r;
      return stub->GetCalibration(&ctx, q, &r);
    }
    case Rpc::kListMotors: { v1::ListMotorsRequest q; v1::ListMotorsResponse r; return stub->ListMotors(&ctx, q, &r); }
    case Rpc::kHistory: { v1::HistoryRequest q; q.set_serial("IPM-AUTH-1"); v1::HistoryResponse r; return stub->History(&ctx, q, &r); }
    case Rpc::kQueryFlux: {
      v1::QueryFluxRequest q; q.set_serial("IPM-AUTH-1"); v1::QueryFluxResponse r;
      return stub->QueryFlux(&ctx, q, &r);
    }
    case Rpc::kExportTable: {
      v1::ExportTableRequest q; q.set_serial("IPM-AUTH-1"); v1::ExportTableResponse r;
      return stub->ExportTable(&ctx, q, &r);
    }
    case Rpc::kFleetStatistics: {
      v1::FleetStatisticsRequest q; v1::FleetStatisticsResponse r; return stub->FleetStatistics(&ctx, q, &r);
    }
    case Rpc::kDiagnose: { v1::DiagnoseRequest q; q.set_serial("IPM-AUTH-1"); v1::DiagnoseResponse r; return stub->Diagnose(&ctx, q, &r); }
    case Rpc::kAudit: { v1::AuditRequest q; q.set_serial("IPM-AUTH-1"); v1::AuditResponse r; return stub->Audit(&ctx, q, &r); }
    case Rpc::kRelease: {
      v1::ReleaseRequest q; q.set_serial("IPM-AUTH-1"); q.set_version(1); v1::ReleaseResponse r;
      return stub->Release(&ctx, q, &r);
    }
    case Rpc::kGetReport: {
      v1::GetReportRequest q; q.set_serial("IPM-AUTH-1"); v1::GetReportResponse r;
      return stub->GetReport(&ctx, q, &r);
    }
  }
  return grpc::Status::CANCELLED;
}

grpc::StatusCode HealthCheck(const std::shared_ptr<grpc::Channel>& ch) {
  grpc::GenericStub gs(ch);
  grpc::CompletionQueue cq;
  grpc::ClientContext c;
  c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  grpc::Slice empty("", 0);
  grpc::ByteBuffer req(&empty, 1), resp;
  auto call = gs.PrepareUnaryCall(&c, "/grpc.health.v1.Health/Check", req, &cq);
  call->StartCall();
  grpc::Status st;
  call->Finish(&resp, &st, reinterpret_cast<void*>(1));
  void* tag = nullptr;
  bool ok = false;
  cq.Next(&tag, &ok);
  return st.error_code();
}

// A token for one identity of every role but health (and the extra keys).
struct Fixture : test_support::AuthorizedServer {
  std::map<Role, std::string> tokens;

  explicit Fixture(const std::string& name, const ServerOptions& base = {}, Keys extra = {}) {
    Keys keys = std::move(extra);
    for (Role r : {Role::kStation, Role::kRelease, Role::kFlasher, Role::kEngineer, Role::kAdmin}) {
      tokens[r] = *NewToken();
      keys.entries.push_back({std::string(RoleName(r)) + "-1", r, io::Sha256Hex(tokens[r]), ""});
    }
    Start(TempPath(name + ".db"), keys, base);
  }
};

TEST(Roles, MatrixOfEveryRoleAndRpc) {
  Fixture f("matrix");
  int denied = 0, allowed = 0;
  for (Role role : {Role::kStation, Role::kRelease, Role::kFlasher, Role::kEngineer, Role::kAdmin}) {
    auto stub = v1::CalibrationService::NewStub(Channel(f.addr(), grpc::InsecureChannelCredentials(), f.tokens[role]));
    for (Rpc rpc : kAllRpcs) {
      const grpc::Status s = Call(stub.get(), rpc);
      SCOPED_TRACE(std::string(RoleName(role)) + " -> " + std::string(RpcName(rpc)) + ": " + s.error_message());
      EXPECT_NE(s.error_code(), grpc::StatusCode::UNAUTHENTICATED);
      if (RoleMayCall(role, rpc)) {
        EXPECT_NE(s.error_code(), grpc::StatusCode::PERMISSION_DENIED);
        ++allowed;
      } else {
        EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED);
        EXPECT_NE(s.error_message().find("may not call " + std::string(RpcName(rpc))), std::string::npos);
        ++denied;
      }
    }
  }
  // The table itself: a flasher only fetches tables, a station cannot read
  // other motors' history or diagnose, nobody but admin has everything.
  EXPECT_FALSE(RoleMayCall(Role::kFlasher, Rpc::kIngestHfResults));
  EXPECT_FALSE(RoleMayCall(Role::kFlasher, Rpc::kFit));
  EXPECT_TRUE(RoleMayCall(Role::kFlasher, Rpc::kExportTable));
  EXPECT_FALSE(RoleMayCall(Role::kStation, Rpc::kDiagnose));
  EXPECT_FALSE(RoleMayCall(Role::kRelease, Rpc::kIngestRecording));
  for (Role r : {Role::kStation, Role::kRelease, Role::kFlasher, Role::kEngineer, Role::kAdmin}) {
    EXPECT_EQ(RoleMayCall(r, Rpc::kGetReport), RoleMayCall(r, Rpc::kGetCalibration)) << RoleName(r);
  }
  EXPECT_GT(denied, 10);
  EXPECT_GT(allowed, 10);
}

TEST(Roles, WithoutAValidCredentialOnlyHealthAnswers) {
  Fixture f("anon");
  for (const std::string& token : {std::string(), std::string("not-a-token"), std::string(64, '0')}) {
    auto ch = Channel(f.addr(), grpc::InsecureChannelCredentials(), token);
    auto stub = v1::CalibrationService::NewStub(ch);
    for (Rpc rpc : kAllRpcs) {
      const grpc::Status s = Call(stub.get(), rpc);
      EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED) << RpcName(rpc) << " token '" << token << "'";
    }
    EXPECT_EQ(HealthCheck(ch), grpc::StatusCode::OK);
  }
  // Nothing anonymous reached the store.
  auto motors = f.store->ListMotors("", false, 0, 10);
  ASSERT_TRUE(motors.ok());
  EXPECT_TRUE(motors->empty());
}

// list_services and file_containing_symbol over one reflection stream.
template <class Svc, class Req, class Resp>
grpc::Status Reflect(const std::shared_ptr<grpc::Channel>& ch, std::vector<std::string>* services,
                     std::string* file) {
  auto stub = Svc::NewStub(ch);
  grpc::ClientContext c;
  c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(20));
  auto stream = stub->ServerReflectionInfo(&c);
  Req list, sym;
  list.set_list_services("");
  sym.set_file_containing_symbol("fluxcal.v1.CalibrationService");
  stream->Write(list);
  stream->Write(sym);
  stream->WritesDone();
  Resp r;
  while (stream->Read(&r)) {
    for (const auto& s : r.list_services_response().service()) services->push_back(s.name());
    if (r.has_file_descriptor_response()) {
      google::protobuf::FileDescriptorProto fd;
      fd.ParseFromString(r.file_descriptor_response().file_descriptor_proto(0));
      *file = fd.name();
    }
  }
  return stream->Finish();
}

// Reflection v1 and v1alpha answer any authenticated identity, whatever its
// role (the API description is the same for all and holds no stored data),
// and nobody without a valid credential.
TEST(Reflection, AnyRoleOverV1AndV1alphaNotAnonymous) {
  namespace r1 = grpc::reflection::v1;
  namespace ra = grpc::reflection::v1alpha;
  Fixture f("reflection");
  for (const auto& [role, token] : f.tokens) {
    auto ch = Channel(f.addr(), grpc::InsecureChannelCredentials(), token);
    for (bool alpha : {false, true}) {
      std::vector<std::string> services;
      std::string file;
      const grpc::Status s =
          alpha ? Reflect<ra::ServerReflection, ra::ServerReflectionRequest, ra::ServerReflectionResponse>(ch, &services, &file)
                : Reflect<r1::ServerReflection, r1::ServerReflectionRequest, r1::ServerReflectionResponse>(ch, &services, &file);
      const std::string what = std::string(RoleName(role)) + (alpha ? " v1alpha" : " v1");
      ASSERT_TRUE(s.ok()) << what << ": " << s.error_message();
      EXPECT_NE(std::find(services.begin(), services.end(), "fluxcal.v1.CalibrationService"), services.end()) << what;
      EXPECT_NE(std::find(services.begin(), services.end(), "grpc.reflection.v1.ServerReflection"), services.end())
          << what;
      EXPECT_NE(std::find(services.begin(), services.end(), "grpc.reflection.v1alpha.ServerReflection"),
                services.end())
          << what;
      EXPECT_EQ(file, "fluxcal/v1/calibration.proto") << what;
    }
  }
  for (const std::string& token : {std::string(), std::string("not-a-token")}) {
    auto ch = Channel(f.addr(), grpc::InsecureChannelCredentials(), token);
    std::vector<std::string> services;
    std::string file;
    EXPECT_EQ((Reflect<r1::ServerReflection, r1::ServerReflectionRequest, r1::ServerReflectionResponse>(ch, &services,
                                                                                                        &file)
                   .error_code()),
              grpc::StatusCode::UNAUTHENTICATED);
    EXPECT_EQ((Reflect<ra::ServerReflection, ra::ServerReflectionRequest, ra::ServerReflectionResponse>(
                   ch, &services, &file)
                   .error_code()),
              grpc::StatusCode::UNAUTHENTICATED);
    EXPECT_TRUE(services.empty());
  }
}

TEST(Roles, AStationIngestsAsItselfAndCannotLoosenTheVerdict) {
  Fixture f("station");
  auto stub = v1::CalibrationService::NewStub(
      Channel(f.addr(), grpc::InsecureChannelCredentials(), f.tokens[Role::kStation]));
  {
    grpc::ClientContext ctx;
    const grpc::Status s = IngestSmallGrid(stub.get(), &ctx, "IPM-AUTH-2", "someone-else");
    EXPECT_EQ(s.error_code(), grpc::StatusCode::PERMISSION_DENIED) << s.error_message();
    EXPECT_NE(s.error_message().find("not the caller's identity 'station-1'"), std::string::npos) << s.error_message();
  }
  EXPECT_TRUE(Call(stub.get(), Rpc::kIngestHfResults).ok());
  {
    sqlite3* h = nullptr;
    ASSERT_EQ(sqlite3_open(f.db.c_str(), &h), SQLITE_OK);
    sqlite3_stmt* st = nullptr;
    sqlite3_prepare_v2(h, "SELECT station FROM runs WHERE serial = 'IPM-AUTH-1'", -1, &st, nullptr);
    ASSERT_EQ(sqlite3_step(st), SQLITE_ROW);
    EXPECT_STREQ(reinterpret_cast<const char*>(sqlite3_column_text(st, 0)), "station-1");
    sqlite3_finalize(st);
    sqlite3_close(h);
  }
  grpc::ClientContext ctx;
  v1::FitRequest q;
  q.set_serial("IPM-AUTH-1");
  q.set_max_rms_relative(1e300);
  v1::FitResponse r;
  const grpc::Status s = stub->Fit(&ctx, q, &r);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(s.error_message().find("may only tighten the server policy"), std::string::npos) << s.error_message();
}

// A run of the twin's analytic motor for `serial` (`scatter` alternates
// Lqq by that fraction point to point: 0.15 fails the 2 % residual policy).
void IngestTwinGrid(v1::CalibrationService::Stub* stub, const std::string& serial, double scatter) {
  sim::MotorParams mp;
  sim::AnalyticMotor m(mp);
  grpc::ClientContext ctx;
  v1::IngestHfResultsResponse r;
  auto w = stub->IngestHfResults(&ctx, &r);
  v1::IngestHfResultsRequest msg;
  msg.set_serial(serial);
  msg.mutable_motor()->set_pole_pairs(4);
  msg.mutable_motor()->set_psi_pm_wb(mp.sat.psi_pm_wb);
  for (int a = 0; a < 6; ++a) {
    for (int b = 0; b < 6; ++b) {
      auto* p = msg.add_points();
      p->set_point_id("p" + std::to_string(6 * a + b));
      p->set_id_a(-100 + 20 * a); p->set_iq_a(20 * b);
      const auto L = m.Inductance(p->id_a(), p->iq_a());
      p->set_ld_h(L.ldd_h); p->set_lq_h(L.lqq_h * (1 + ((a + b) % 2 ? scatter : -scatter)));
      p->set_ldq_h(L.ldq_h);
      p->set_temperature_c(25); p->set_reliable(true);
    }
  }
  w->Write(msg);
  w->WritesDone();
  EXPECT_TRUE(w->Finish().ok());
}

// GetReport goes with GetCalibration: a flasher (no read right) is refused
// naming the RPC, the readers get the page. Its fleet section names other
// serials, so it is only on the pages of roles that may call
// FleetStatistics, whatever the request asks.
TEST(Roles, GetReportReadsLikeGetCalibrationAndTheFleetStaysWithEngineers) {
  Fixture f("report");
  auto as = [&](Role r) {
    return v1::CalibrationService::NewStub(Channel(f.addr(), grpc::InsecureChannelCredentials(), f.tokens[r]));
  };
  auto admin = as(Role::kAdmin);
  {
    IngestTwinGrid(admin.get(), "IPM-RPT-A", 0.0);
    if (::testing::Test::HasFailure()) return;
    grpc::ClientContext fc;
    v1::FitRequest fq;
    fq.set_serial("IPM-RPT-A");
    v1::FitResponse fr;
    ASSERT_TRUE(admin->Fit(&fc, fq, &fr).ok());
  }
  auto report = [&](Role r, v1::GetReportResponse* resp) {
    grpc::ClientContext c;
    c.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
    v1::GetReportRequest q;
    q.set_serial("IPM-RPT-A");
    q.set_include_fleet(true);
    return as(r)->GetReport(&c, q, resp);
  };
  v1::GetReportResponse page;
  const grpc::Status denied = report(Role::kFlasher, &page);
  EXPECT_EQ(denied.error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_NE(denied.error_message().find("'flasher-1' (role flasher) may not call GetReport"), std::string::npos)
      << denied.error_message();
  EXPECT_TRUE(page.html().empty());
  for (Role r : {Role::kStation, Role::kRelease, Role::kEngineer, Role::kAdmin}) {
    v1::GetReportResponse p;
    const grpc::Status s = report(r, &p);
    ASSERT_TRUE(s.ok()) << RoleName(r) << ": " << s.error_message();
    EXPECT_NE(p.html().find("IPM-RPT-A"), std::string::npos);
    const bool fleet = RoleMayCall(r, Rpc::kFleetStatistics);
    EXPECT_EQ(p.fleet_included(), fleet) << RoleName(r);
    EXPECT_EQ(p.html().find("<h2>Fleet</h2>") != std::string::npos, fleet) << RoleName(r);
  }
}

v1::FitResponse FitAs(v1::CalibrationService::Stub* stub, const std::string& serial, double max_rms) {
  grpc::ClientContext c;
  v1::FitRequest q;
  q.set_serial(serial);
  q.set_max_rms_relative(max_rms);
  v1::FitResponse r;
  EXPECT_TRUE(stub->Fit(&c, q, &r).ok());
  return r;
}

// Release and flashing: a failed calibration cannot be released; flashers
// see nothing before a release and then exactly the released version, even
// after a newer (unreleased) fit; a station cannot release.
TEST(Roles, OnlyAReleasedPassingCalibrationIsFlashed) {
  Fixture f("release");
  auto as = [&](Role r) {
    return v1::CalibrationService::NewStub(Channel(f.addr(), grpc::InsecureChannelCredentials(), f.tokens[r]));
  };
  auto admin = as(Role::kAdmin), release = as(Role::kRelease), flasher = as(Role::kFlasher), station = as(Role::kStation);
  auto ingest = [&](double scatter) { IngestTwinGrid(admin.get(), "IPM-REL-1", scatter); };
  auto fit = [&](double max_rms) { return FitAs(admin.get(), "IPM-REL-1", max_rms); };
  auto release_v = [&](v1::CalibrationService::Stub* st, int v) {
    grpc::ClientContext c;
    v1::ReleaseRequest q;
    q.set_serial("IPM-REL-1");
    q.set_version(v);
    v1::ReleaseResponse r;
    return st->Release(&c, q, &r);
  };
  auto flash = [&](int v, v1::ExportTableResponse* r) {
    grpc::ClientContext c;
    v1::ExportTableRequest q;
    q.set_serial("IPM-REL-1");
    q.set_version(v);
    q.set_points(8);
    return flasher->ExportTable(&c, q, r);
  };
  ingest(0.0);
  const auto v1r = fit(0);
  ASSERT_TRUE(v1r.pass());
  ingest(0.15);                 // a bad run: +-15 % scatter fails the 2 % policy
  const auto v2r = fit(0);
  ASSERT_FALSE(v2r.pass()) << v2r.calibration().verdict();
  v1::ExportTableResponse e;
  EXPECT_EQ(flash(0, &e).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(release_v(station.get(), 1).error_code(), grpc::StatusCode::PERMISSION_DENIED);
  EXPECT_EQ(release_v(release.get(), 2).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  EXPECT_EQ(release_v(release.get(), 9).error_code(), grpc::StatusCode::NOT_FOUND);
  ASSERT_TRUE(release_v(release.get(), 1).ok());
  EXPECT_EQ(release_v(release.get(), 1).error_code(), grpc::StatusCode::ALREADY_EXISTS);
  ASSERT_TRUE(flash(0, &e).ok());
  EXPECT_EQ(e.version(), 1);
  EXPECT_TRUE(e.released());
  EXPECT_EQ(e.verdict(), "pass");
  // The file itself says so (a flashing tool may see only the file).
  EXPECT_NE(e.data().find("# verdict: pass\n"), std::string::npos);
  EXPECT_NE(e.data().find("# release_state: released\n"), std::string::npos);
  EXPECT_NE(e.data().find("# calibration_version: 1\n"), std::string::npos);
  EXPECT_EQ(flash(2, &e).error_code(), grpc::StatusCode::FAILED_PRECONDITION);
  // An engineer may export any version and sees its state.
  grpc::ClientContext c;
  v1::ExportTableRequest q;
  q.set_serial("IPM-REL-1");
  q.set_points(8);
  v1::ExportTableResponse er;
  ASSERT_TRUE(as(Role::kEngineer)->ExportTable(&c, q, &er).ok());
  EXPECT_EQ(er.version(), 2);
  EXPECT_FALSE(er.released());
  EXPECT_NE(er.verdict(), "pass");
  EXPECT_NE(er.data().find("# verdict: " + er.verdict() + "\n"), std::string::npos);
  EXPECT_NE(er.data().find("# release_state: not released\n"), std::string::npos);
  // The audit trail names who did each write, with the client's request id
  // where it sent one; a flasher may not read it.
  grpc::ClientContext ac;
  ac.AddMetadata("x-request-id", "bench-7-0001");
  v1::AuditRequest aq;
  aq.set_serial("IPM-REL-1");
  v1::AuditResponse ar;
  ASSERT_TRUE(as(Role::kEngineer)->Audit(&ac, aq, &ar).ok());
  std::vector<std::string> seen;
  for (const auto& e : ar.entries()) seen.push_back(e.rpc() + ":" + e.identity() + ":" + e.role());
  EXPECT_EQ(seen, (std::vector<std::string>{"IngestHfResults:admin-1:admin", "Fit:admin-1:admin",
                                            "IngestHfResults:admin-1:admin", "Fit:admin-1:admin",
                                            "Release:release-1:release"}));
  for (const auto& e : ar.entries()) {
    EXPECT_NE(e.peer().find("127.0.0.1"), std::string::npos) << e.peer();
    EXPECT_FALSE(e.request_id().empty());
    EXPECT_FALSE(e.utc().empty());
  }
  EXPECT_EQ(ar.entries(4).detail(), "released version 1");
  grpc::ClientContext fc;
  v1::AuditResponse fr;
  EXPECT_EQ(flasher->Audit(&fc, aq, &fr).error_code(), grpc::StatusCode::PERMISSION_DENIED);
  // The request id a client sends is kept.
  grpc::ClientContext rc;
  rc.AddMetadata("x-request-id", "bench-7-0002");
  v1::ReleaseRequest rq;
  rq.set_serial("IPM-REL-1");
  rq.set_version(1);
  v1::ReleaseResponse rr;
  EXPECT_EQ(release->Release(&rc, rq, &rr).error_code(), grpc::StatusCode::ALREADY_EXISTS);
}

// Issue 24: a release INSERTed into the SQLite file behind the service
// made a failing calibration flashable. The flasher's export now re-checks
// verdict and chains at export time: the unlinked release is DATA_LOSS; one
// with a well-formed link forged beside it is still FAILED_PRECONDITION by
// its verdict; the honest release keeps flashing; `verify-db` names both.
// With an anchor file the service appends the chain heads after every fit
// and release.
TEST(Roles, AReleaseMadeBehindTheServiceIsNotFlashed) {
  Fixture f("forged");
  const std::string anchor = TempPath("forged.anchor");
  fs::remove(anchor);
  f.service->set_anchor_file(anchor);
  auto as = [&](Role r) {
    return v1::CalibrationService::NewStub(Channel(f.addr(), grpc::InsecureChannelCredentials(), f.tokens[r]));
  };
  auto admin = as(Role::kAdmin), release = as(Role::kRelease), flasher = as(Role::kFlasher);
  IngestTwinGrid(admin.get(), "IPM-FORGE", 0.0);
  ASSERT_TRUE(FitAs(admin.get(), "IPM-FORGE", 0).pass());
  IngestTwinGrid(admin.get(), "IPM-FORGE", 0.15);
  ASSERT_FALSE(FitAs(admin.get(), "IPM-FORGE", 0).pass());
  {
    grpc::ClientContext c;
    v1::ReleaseRequest q;
    q.set_serial("IPM-FORGE");
    q.set_version(1);
    v1::ReleaseResponse r;
    ASSERT_TRUE(release->Release(&c, q, &r).ok());
  }
  auto flash = [&](int v, v1::ExportTableResponse* r) {
    grpc::ClientContext c;
    v1::ExportTableRequest q;
    q.set_serial("IPM-FORGE");
    q.set_version(v);
    q.set_points(8);
    return flasher->ExportTable(&c, q, r);
  };
  v1::ExportTableResponse e;
  ASSERT_TRUE(flash(0, &e).ok());
  EXPECT_EQ(e.version(), 1);
  // Two fits and a release, each followed by an anchor line.
  auto a = pipeline::ReadAnchorFile(anchor);
  ASSERT_TRUE(a.ok()) << a.status();
  EXPECT_EQ(a->lines, 3);
  ASSERT_EQ(a->head.calibrations.size(), 1u);
  EXPECT_EQ(a->head.calibrations[0].version, 2);
  EXPECT_EQ(a->head.calibrations[0].row_sha256, f.store->ChainLink("IPM-FORGE", 2)->row_sha256);
  EXPECT_EQ(a->head.release_seq, 1);
  // Behind the service: the failing version 2 released by an INSERT.
  sqlite3* h = nullptr;
  ASSERT_EQ(sqlite3_open(f.db.c_str(), &h), SQLITE_OK);
  auto sql = [&](const std::string& q) { return sqlite3_exec(h, q.c_str(), nullptr, nullptr, nullptr) == SQLITE_OK; };
  ASSERT_TRUE(sql("INSERT INTO releases (serial, version, released_by, released_utc) "
                  "VALUES ('IPM-FORGE', 2, 'release-1', '2030-01-01T00:00:00Z')"));
  grpc::Status s = flash(0, &e);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::DATA_LOSS) << s.error_message();
  EXPECT_NE(s.error_message().find("IPM-FORGE v2: release without a chain link"), std::string::npos)
      << s.error_message();
  EXPECT_EQ(flash(2, &e).error_code(), grpc::StatusCode::DATA_LOSS);
  ASSERT_TRUE(flash(1, &e).ok()) << "the honest release still flashes";
  // A link forged with the published formula: the chain is satisfied, the
  // verdict is not.
  const auto first = f.store->ReleaseLinkAt(1);
  ASSERT_TRUE(first.ok());
  const std::string cal_sha = f.store->ChainLink("IPM-FORGE", 2)->row_sha256;
  const storage::ReleaseRow forged{"IPM-FORGE", 2, "release-1", "2030-01-01T00:00:00Z"};
  ASSERT_TRUE(sql("INSERT INTO release_chain (seq, serial, version, calibration_sha256, prev_sha256, row_sha256) "
                  "VALUES (2, 'IPM-FORGE', 2, '" + cal_sha + "', '" + first->row_sha256 + "', '" +
                  storage::ReleaseRowSha256(first->row_sha256, 2, forged, cal_sha) + "')"));
  sqlite3_close(h);
  s = flash(0, &e);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << s.error_message();
  EXPECT_NE(s.error_message().find("has verdict 'fail"), std::string::npos) << s.error_message();
  const std::string out = TempPath("forged.out");
  const int rc = std::system((std::string(FLUXCAL_BINARY) + " admin verify-db --db " + f.db + " > " + out).c_str());
  const std::string report = io::ReadFileToString(out).value_or("");
  fs::remove(out);
  EXPECT_EQ(WEXITSTATUS(rc), 1) << report;
  EXPECT_NE(report.find("IPM-FORGE v2 (release #2): released with verdict 'fail"), std::string::npos) << report;
  fs::remove(anchor);
}

TEST(Audit, RequestIdFromTheClientIsKept) {
  Fixture f("audit-id");
  auto st = v1::CalibrationService::NewStub(
      Channel(f.addr(), grpc::InsecureChannelCredentials(), f.tokens[Role::kStation]));
  grpc::ClientContext ctx;
  ctx.AddMetadata("x-request-id", "eol-7-run-0042");
  ASSERT_TRUE(IngestSmallGrid(st.get(), &ctx, "IPM-AUD-1").ok());
  auto rows = f.store->AuditOf("IPM-AUD-1");
  ASSERT_TRUE(rows.ok());
  ASSERT_EQ(rows->size(), 1u);
  EXPECT_EQ((*rows)[0].request_id, "eol-7-run-0042");
  EXPECT_EQ((*rows)[0].identity, "station-1");
  EXPECT_EQ((*rows)[0].role, "station");
  EXPECT_NE((*rows)[0].detail.find("6 points"), std::string::npos) << (*rows)[0].detail;
}

// A throwaway CA, a server certificate for 127.0.0.1 and a client
// certificate, made with Debian's openssl.
struct Pki {
  std::string dir = TempPath("pki");
  Pki() {
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string d = dir;
    const std::string script =
        "set -e; cd " + d + "\n"
        "openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout ca.key -out ca.pem "
        "-days 2 -subj /CN=fluxcal-test-ca 2>/dev/null\n"
        "mk() { openssl req -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -keyout $1.key -out $1.csr "
        "-subj /CN=$2 2>/dev/null; printf '%s' \"$3\" > $1.ext; openssl x509 -req -in $1.csr -CA ca.pem -CAkey ca.key "
        "-CAcreateserial -out $1.pem -days 2 -extfile $1.ext 2>/dev/null; }\n"
        "mk server localhost 'subjectAltName=IP:127.0.0.1,DNS:localhost'\n"
        "mk client station-cert-7 'extendedKeyUsage=clientAuth'\n"
        "mk stranger unknown-host 'extendedKeyUsage=clientAuth'\n";
    std::ofstream(d + "/make.sh") << script;
    ok = std::system(("bash " + d + "/make.sh").c_str()) == 0;
  }
  ~Pki() { fs::remove_all(dir); }
  std::string Read(const std::string& f) const { return *io::ReadFileToString(dir + "/" + f); }
  bool ok = false;
};

TEST(Tls, ServerCertificateAndMutualTls) {
  Pki pki;
  ASSERT_TRUE(pki.ok) << "openssl could not make the test CA";
  ServerOptions opt;
  opt.tls_cert_pem = pki.Read("server.pem");
  opt.tls_key_pem = pki.Read("server.key");
  {
    Fixture f("tls", opt);
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = pki.Read("ca.pem");
    auto stub = v1::CalibrationService::NewStub(Channel(f.addr(), grpc::SslCredentials(ssl), f.tokens[Role::kAdmin]));
    EXPECT_TRUE(Call(stub.get(), Rpc::kListMotors).ok());
    // A plaintext client cannot talk to the TLS port.
    auto plain = v1::CalibrationService::NewStub(
        Channel(f.addr(), grpc::InsecureChannelCredentials(), f.tokens[Role::kAdmin]));
    EXPECT_EQ(Call(plain.get(), Rpc::kListMotors).error_code(), grpc::StatusCode::UNAVAILABLE);
    // Nor a client that does not trust the CA.
    auto untrusting = v1::CalibrationService::NewStub(
        Channel(f.addr(), grpc::SslCredentials(grpc::SslCredentialsOptions()), f.tokens[Role::kAdmin]));
    EXPECT_EQ(Call(untrusting.get(), Rpc::kListMotors).error_code(), grpc::StatusCode::UNAVAILABLE);
  }
  opt.client_ca_pem = pki.Read("ca.pem");
  Keys certs;
  certs.entries.push_back({"station-7", Role::kStation, "", "station-cert-7"});
  Fixture f("mtls", opt, certs);
  auto with_cert = [&](const std::string& who) {
    grpc::SslCredentialsOptions ssl;
    ssl.pem_root_certs = pki.Read("ca.pem");
    if (!who.empty()) {
      ssl.pem_cert_chain = pki.Read(who + ".pem");
      ssl.pem_private_key = pki.Read(who + ".key");
    }
    return v1::CalibrationService::NewStub(Channel(f.addr(), grpc::SslCredentials(ssl), ""));
  };
  auto station = with_cert("client");
  EXPECT_TRUE(Call(station.get(), Rpc::kIngestHfResults).ok());
  EXPECT_EQ(Call(station.get(), Rpc::kDiagnose).error_code(), grpc::StatusCode::PERMISSION_DENIED);
  auto stranger = with_cert("stranger");
  const grpc::Status s = Call(stranger.get(), Rpc::kListMotors);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::UNAUTHENTICATED);
  EXPECT_NE(s.error_message().find("'unknown-host' is not in the service's keys"), std::string::npos) << s.error_message();
  // Without a client certificate (and no token) the caller is anonymous.
  EXPECT_EQ(Call(with_cert("").get(), Rpc::kListMotors).error_code(), grpc::StatusCode::UNAUTHENTICATED);
}

TEST(Tls, RequiredClientCertificate) {
  Pki pki;
  ASSERT_TRUE(pki.ok);
  ServerOptions opt;
  opt.tls_cert_pem = pki.Read("server.pem");
  opt.tls_key_pem = pki.Read("server.key");
  opt.client_ca_pem = pki.Read("ca.pem");
  opt.require_client_cert = true;
  Fixture f("mtls-required", opt);
  grpc::SslCredentialsOptions ssl;
  ssl.pem_root_certs = pki.Read("ca.pem");
  // A valid token is not enough: the handshake needs a certificate.
  auto stub = v1::CalibrationService::NewStub(Channel(f.addr(), grpc::SslCredentials(ssl), f.tokens[Role::kAdmin]));
  EXPECT_EQ(Call(stub.get(), Rpc::kListMotors).error_code(), grpc::StatusCode::UNAVAILABLE);
}

int RunFluxcal(const std::string& args, std::string* err) {
  const std::string out = TempPath("serve.err");
  const int rc = std::system((std::string(FLUXCAL_BINARY) + " " + args + " 2>" + out + " >/dev/null").c_str());
  *err = io::ReadFileToString(out).value_or("");
  fs::remove(out);
  return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
}

TEST(Serve, RefusesUnsafeListenSetups) {
  std::string err;
  const std::string db = TempPath("refuse.db");
  EXPECT_EQ(RunFluxcal("serve --db " + db + " --listen 0.0.0.0:0", &err), 2);
  EXPECT_NE(err.find("not a loopback address: give --tls-cert and --tls-key"), std::string::npos) << err;
  EXPECT_EQ(RunFluxcal("serve --db " + db + " --listen 0.0.0.0:0 --insecure", &err), 2);
  EXPECT_NE(err.find("give --auth KEYS.json"), std::string::npos) << err;
  EXPECT_EQ(RunFluxcal("serve --db " + db + " --tls-cert /nonexistent.pem --tls-key x", &err), 2);
  EXPECT_NE(err.find("cannot read"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(db));
  EXPECT_TRUE(io::IsLoopbackAddress("127.0.0.1:50051"));
  EXPECT_TRUE(io::IsLoopbackAddress("localhost:1"));
  EXPECT_TRUE(io::IsLoopbackAddress("[::1]:1"));
  EXPECT_FALSE(io::IsLoopbackAddress("0.0.0.0:50051"));
  EXPECT_FALSE(io::IsLoopbackAddress("[::]:50051"));
  EXPECT_FALSE(io::IsLoopbackAddress("10.0.0.5:50051"));
  // Spelt like loopback, but a DNS name that does not resolve (or resolves
  // elsewhere): TLS and --auth needed, like any other address.
  EXPECT_FALSE(io::IsLoopbackAddress("127.plant.example:50051"));
  EXPECT_EQ(RunFluxcal("serve --db " + db + " --listen 127.plant.example:0", &err), 2);
  EXPECT_NE(err.find("not a loopback address: give --tls-cert and --tls-key"), std::string::npos) << err;
  EXPECT_NE(err.find("127.plant.example:0 does not resolve"), std::string::npos) << err;
  EXPECT_FALSE(fs::exists(db));
}

TEST(Keys, AdminCommandsRoundTrip) {
  const std::string keys = TempPath("keys.json");
  fs::remove(keys);
  std::string err;
  EXPECT_EQ(RunFluxcal("admin add-key --keys " + keys + " --name st-1 --role station", &err), 0) << err;
  EXPECT_EQ(RunFluxcal("admin add-cert --keys " + keys + " --name st-2 --role flasher --cn host-2", &err), 0) << err;
  EXPECT_EQ(RunFluxcal("admin add-key --keys " + keys + " --name st-1 --role admin", &err), 1);
  EXPECT_NE(err.find("exists"), std::string::npos) << err;
  EXPECT_EQ(RunFluxcal("admin add-key --keys " + keys + " --name x --role superuser", &err), 1);
  auto k = LoadKeys(keys);
  ASSERT_TRUE(k.ok()) << k.status();
  ASSERT_EQ(k->entries.size(), 2u);
  EXPECT_EQ(k->entries[0].token_sha256.size(), 64u);
  EXPECT_EQ(k->entries[1].cert_cn, "host-2");
  EXPECT_EQ(fs::status(keys).permissions() & (fs::perms::group_all | fs::perms::others_all), fs::perms::none);
  EXPECT_EQ(RunFluxcal("admin revoke --keys " + keys + " --name st-1", &err), 0) << err;
  EXPECT_EQ(LoadKeys(keys)->entries.size(), 1u);
  fs::remove(keys);
}

}  // namespace
}  // namespace fluxcal::server
