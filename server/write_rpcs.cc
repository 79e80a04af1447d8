// The unary RPCs that store something: Fit (a new version), Diagnose
// (a diagnosed version), Release.
#include "server/service.h"

#include <grpcpp/grpcpp.h>

#include "absl/strings/str_cat.h"
#include "nlohmann/json.hpp"
#include "pipeline/diagnose.h"
#include "pipeline/pipeline.h"
#include "server/internal.h"
#include "server/validation.h"

namespace fluxcal::server {

using internal::CancelledBy;
using internal::StoppedOr;
using internal::ToProto;

grpc::Status CalibrationServiceImpl::Fit(grpc::ServerContext* ctx, const v1::FitRequest* req, v1::FitResponse* resp) {
  auto who = AdmitForSerial(ctx, Rpc::kFit, req->serial());
  if (!who.ok()) return ToGrpcStatus(who.status());
  // Verdict tolerances are policy (pipeline::RequestedTolerances): a client
  // may tighten them, never loosen them.
  auto tol = pipeline::RequestedTolerances(req->max_rms_relative(), req->psi_pm_tolerance_relative());
  if (!tol.ok()) return ToGrpcStatus(tol.status());
  // Model and verdict are known before the store call, the version only
  // inside it: the detail is formed there from the row the pipeline stores.
  const auto audit = AuditFor(ctx, *who, Rpc::kFit, req->serial(), nullptr);
  auto row = pipeline::FitSerial(*store_, req->serial(), req->model(), *tol, &audit, CancelledBy(ctx));
  if (!row.ok()) return StoppedOr(ctx, row.status());
  AnchorAfterWrite(req->serial());
  ToProto(*row, resp->mutable_calibration());
  resp->set_pass(row->verdict == "pass");
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::Diagnose(grpc::ServerContext* ctx, const v1::DiagnoseRequest* req,
                                              v1::DiagnoseResponse* resp) {
  auto who = AdmitForSerial(ctx, Rpc::kDiagnose, req->serial());
  if (!who.ok()) return ToGrpcStatus(who.status());
  auto rep = pipeline::DiagnoseStored(*store_, req->serial(), CancelledBy(ctx));
  if (!rep.ok()) return StoppedOr(ctx, rep.status());
  resp->set_serial(req->serial());
  resp->set_verdict(rep->verdict);
  resp->set_report_json(pipeline::DiagnosisJson(*rep).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
  for (const auto& f : rep->findings) resp->add_effects(f.effect);
  if (req->store_calibration()) {
    const auto audit = AuditFor(ctx, *who, Rpc::kDiagnose, req->serial(), nullptr);
    auto row = pipeline::StoreDiagnosedCalibration(*store_, req->serial(), *rep, pipeline::FitTolerances{}, &audit);
    if (!row.ok()) return StoppedOr(ctx, row.status());
    AnchorAfterWrite(req->serial());
    resp->set_stored_version(row->version);
    resp->set_stored_verdict(row->verdict);
  }
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::Release(grpc::ServerContext* ctx, const v1::ReleaseRequest* req,
                                             v1::ReleaseResponse* resp) {
  auto who = AdmitForSerial(ctx, Rpc::kRelease, req->serial());
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (req->version() <= 0) {
    return ToGrpcStatus(absl::InvalidArgumentError("version: a release names the version it approves (> 0)"));
  }
  const auto audit = AuditFor(ctx, *who, Rpc::kRelease, req->serial(),
                              [](int64_t version, bool) { return absl::StrCat("released version ", version); });
  if (auto s = pipeline::ReleaseVersion(*store_, req->serial(), req->version(), who->name, &audit); !s.ok()) return ToGrpcStatus(s);
  AnchorAfterWrite(req->serial());
  resp->set_serial(req->serial());
  resp->set_version(req->version());
  resp->set_released_by(who->name);
  return grpc::Status::OK;
}

}  // namespace fluxcal::server
