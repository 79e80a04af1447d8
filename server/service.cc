// The service's common machinery: statuses mapped to gRPC's in one place,
// admission (identity and in-flight limits), the audit context of a write,
// the anchor after one, and the helpers the RPC files share
// (server/internal.h). The RPCs: ingest_rpcs.cc, read_rpcs.cc,
// write_rpcs.cc; starting the server: start.cc.
#include "server/service.h"

#include <grpcpp/grpcpp.h>

#include <chrono>
#include <cstdio>

#include "absl/strings/str_cat.h"
#include "pipeline/anchor.h"
#include "pipeline/pipeline.h"
#include "server/internal.h"
#include "server/validation.h"

namespace fluxcal::server {

grpc::Status ToGrpcStatus(const absl::Status& s) {
  if (s.ok()) return grpc::Status::OK;
  grpc::StatusCode c = grpc::StatusCode::INTERNAL;
  switch (s.code()) {
    case absl::StatusCode::kInvalidArgument: c = grpc::StatusCode::INVALID_ARGUMENT; break;
    case absl::StatusCode::kNotFound: c = grpc::StatusCode::NOT_FOUND; break;
    case absl::StatusCode::kAlreadyExists: c = grpc::StatusCode::ALREADY_EXISTS; break;
    case absl::StatusCode::kFailedPrecondition: c = grpc::StatusCode::FAILED_PRECONDITION; break;
    case absl::StatusCode::kResourceExhausted: c = grpc::StatusCode::RESOURCE_EXHAUSTED; break;
    case absl::StatusCode::kUnavailable: c = grpc::StatusCode::UNAVAILABLE; break;
    case absl::StatusCode::kDeadlineExceeded: c = grpc::StatusCode::DEADLINE_EXCEEDED; break;
    case absl::StatusCode::kCancelled: c = grpc::StatusCode::CANCELLED; break;
    case absl::StatusCode::kAborted: c = grpc::StatusCode::ABORTED; break;   // e.g. a database deadlock: retry
    case absl::StatusCode::kDataLoss: c = grpc::StatusCode::DATA_LOSS; break;
    case absl::StatusCode::kPermissionDenied: c = grpc::StatusCode::PERMISSION_DENIED; break;
    case absl::StatusCode::kUnauthenticated: c = grpc::StatusCode::UNAUTHENTICATED; break;
    case absl::StatusCode::kOutOfRange: c = grpc::StatusCode::OUT_OF_RANGE; break;
    case absl::StatusCode::kUnimplemented: c = grpc::StatusCode::UNIMPLEMENTED; break;
    default: break;
  }
  std::string msg(s.message());
  if (msg.size() > kMaxStatusMessageBytes) msg = msg.substr(0, kMaxStatusMessageBytes - 3) + "...";
  return grpc::Status(c, msg);
}

namespace internal {

pipeline::CancelledFn CancelledBy(grpc::ServerContext* ctx) {
  return [ctx] { return ctx->IsCancelled() || std::chrono::system_clock::now() >= ctx->deadline(); };
}

// Work stopped by CancelledBy: DEADLINE_EXCEEDED when the client's deadline
// passed, CANCELLED when the client went away; other errors as they are.
grpc::Status StoppedOr(grpc::ServerContext* ctx, const absl::Status& s) {
  if (s.code() == absl::StatusCode::kCancelled && std::chrono::system_clock::now() >= ctx->deadline()) {
    return grpc::Status(grpc::StatusCode::DEADLINE_EXCEEDED,
                        absl::StrCat("the client's deadline passed; nothing was stored (", s.message(), ")"));
  }
  return ToGrpcStatus(s);
}

void ToProto(const storage::CalibrationRow& c, v1::CalibrationRecord* r) {
  r->set_serial(c.serial);
  r->set_version(c.version);
  r->set_created_utc(c.created_utc);
  r->set_model(c.model);
  r->set_psi_pm_wb(c.psi_pm_wb);
  r->set_rms_relative(c.rms_relative);
  r->set_verdict(c.verdict);
  r->set_calibration_json(c.calibration_json);
  r->set_run_id(c.run_id);
}

// The station a run is recorded under: an authenticated station is itself,
// whatever the message claims (a different claim is refused); others
// (admin, open mode) may name one.
absl::Status StationOf(const Identity& who, const std::string& claimed, std::string* station) {
  if (who.via == "open" || who.role != Role::kStation) {
    *station = claimed.empty() && who.via != "open" ? who.name : claimed;
    return absl::OkStatus();
  }
  if (!claimed.empty() && claimed != who.name) {
    return absl::PermissionDeniedError(
        absl::StrCat("station_id: '", claimed, "' is not the caller's identity '", who.name, "'"));
  }
  *station = who.name;
  return absl::OkStatus();
}

// A stream problem at message `m` (0-based): the status with "message m: "
// in front and "; nothing stored" after, its code kept.
grpc::Status AtMessage(int64_t m, const absl::Status& s) {
  return ToGrpcStatus(absl::Status(s.code(), absl::StrCat("message ", m, ": ", s.message(), "; nothing stored")));
}

}  // namespace internal

void CalibrationServiceImpl::AnchorAfterWrite(const std::string& serial) {
  if (anchor_file_.empty()) return;
  // The write is committed whatever happens here: a failure is logged for
  // the operator, not returned (a client would retry a write that is done).
  if (auto s = pipeline::AppendAnchorEvent(*store_, anchor_file_, serial); !s.ok()) {
    std::fprintf(stderr, "fluxcal serve: anchor after a write of '%s' not written: %s\n", serial.c_str(),
                 std::string(s.message()).c_str());
  }
}

absl::StatusOr<Admission> CalibrationServiceImpl::Admit(grpc::ServerContext* ctx, Rpc rpc) {
  auto who = auth_->Authorize(*ctx, rpc);
  if (!who.ok()) return who.status();
  auto lease = limiter_->Acquire(who->name);
  if (!lease.ok()) return lease.status();
  Admission a;
  static_cast<Identity&>(a) = std::move(*who);
  a.lease = std::move(*lease);
  return a;
}

absl::StatusOr<Admission> CalibrationServiceImpl::AdmitForSerial(grpc::ServerContext* ctx, Rpc rpc,
                                                                 const std::string& serial) {
  auto who = Admit(ctx, rpc);
  if (!who.ok()) return who.status();
  if (auto s = ValidateSerial(serial); !s.ok()) return s;
  return who;
}

storage::AuditContext CalibrationServiceImpl::AuditFor(grpc::ServerContext* ctx, const Identity& who, Rpc rpc,
                                                      const std::string& serial,
                                                      std::function<std::string(int64_t, bool)> detail) {
  storage::AuditContext out;
  out.detail = std::move(detail);
  storage::AuditRow& a = out.row;
  a.identity = who.name;
  a.role = std::string(RoleName(who.role));
  a.peer = ctx->peer().substr(0, 128);
  const auto& md = ctx->client_metadata();
  if (auto it = md.find("x-request-id"); it != md.end()) {
    const std::string id(it->second.data(), it->second.size());
    if (ValidateIdentifier(id, "x-request-id").ok()) a.request_id = id;
  }
  if (a.request_id.empty()) a.request_id = NewToken().value_or("none").substr(0, 16);
  a.rpc = std::string(RpcName(rpc));
  a.serial = serial;
  return out;
}

}  // namespace fluxcal::server
