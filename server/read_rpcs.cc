// The unary RPCs that read: a calibration, the motors and their history,
// flux queries, table exports (signed), fleet statistics, the audit trail
// and the report page.
#include "server/service.h"

#include <cmath>

#include <grpcpp/grpcpp.h>

#include <iterator>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "pipeline/export.h"
#include "pipeline/pipeline.h"
#include "pipeline/report.h"
#include "pipeline/signing.h"
#include "server/internal.h"
#include "server/validation.h"

namespace fluxcal::server {

using internal::CancelledBy;
using internal::StoppedOr;
using internal::ToProto;

grpc::Status CalibrationServiceImpl::GetCalibration(grpc::ServerContext* ctx, const v1::GetCalibrationRequest* req,
                                                    v1::CalibrationRecord* resp) {
  auto who = AdmitForSerial(ctx, Rpc::kGetCalibration, req->serial());
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateVersion(req->version()); !s.ok()) return ToGrpcStatus(s);
  auto row = pipeline::GetCalibrationRecord(*store_, req->serial(), req->version());
  if (!row.ok()) return ToGrpcStatus(row.status());
  ToProto(*row, resp);
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::ListMotors(grpc::ServerContext* ctx, const v1::ListMotorsRequest* req,
                                                v1::ListMotorsResponse* resp) {
  auto who = Admit(ctx, Rpc::kListMotors);
  if (!who.ok()) return ToGrpcStatus(who.status());
  int size = req->page_size() == 0 ? 50 : req->page_size();
  if (size < 0 || size > 1000) return ToGrpcStatus(absl::InvalidArgumentError("page_size: must be 0..1000"));
  auto token = ParsePageToken(req->page_token());
  if (!token.ok()) return ToGrpcStatus(token.status());
  const int offset = *token;
  if (req->serial_prefix().size() > 64) return ToGrpcStatus(absl::InvalidArgumentError("serial_prefix: at most 64 characters"));
  auto page = pipeline::ListMotorsPage(*store_, req->serial_prefix(), req->only_failed(), offset, size);
  if (!page.ok()) return ToGrpcStatus(page.status());
  if (who->role == Role::kHealth) return grpc::Status::OK;   // the database answered; no data for a health check
  for (const auto& r : page->motors) {
    auto* m = resp->add_motors();
    m->set_serial(r.serial); m->set_latest_version(r.latest_version); m->set_verdict(r.verdict);
    m->set_runs(r.runs); m->set_updated_utc(r.updated_utc);
  }
  if (page->next_offset) resp->set_next_page_token(std::to_string(*page->next_offset));
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::History(grpc::ServerContext* ctx, const v1::HistoryRequest* req,
                                             v1::HistoryResponse* resp) {
  auto who = AdmitForSerial(ctx, Rpc::kHistory, req->serial());
  if (!who.ok()) return ToGrpcStatus(who.status());
  auto rows = pipeline::MotorHistory(*store_, req->serial());
  if (!rows.ok()) return ToGrpcStatus(rows.status());
  resp->set_serial(req->serial());
  for (const auto& r : *rows) {
    auto* e = resp->add_events();
    e->set_created_utc(r.created_utc); e->set_kind(r.kind); e->set_run_id(r.run_id);
    e->set_version(r.version); e->set_detail(r.detail);
  }
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::QueryFlux(grpc::ServerContext* ctx, const v1::QueryFluxRequest* req,
                                               v1::QueryFluxResponse* resp) {
  auto who = AdmitForSerial(ctx, Rpc::kQueryFlux, req->serial());
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateVersion(req->version()); !s.ok()) return ToGrpcStatus(s);
  if (req->points_size() > kMaxQueryPoints) {
    return ToGrpcStatus(absl::ResourceExhaustedError(absl::StrCat("points: at most ", kMaxQueryPoints, " per call")));
  }
  for (int k = 0; k < req->points_size(); ++k) {
    if (auto s = ValidateOperatingPoint(req->points(k), k); !s.ok()) return ToGrpcStatus(s);
  }
  std::vector<std::pair<double, double>> pts;
  pts.reserve(req->points_size());
  for (const auto& p : req->points()) pts.push_back({p.id_a(), p.iq_a()});
  auto q = pipeline::QueryFlux(*store_, req->serial(), req->version(), pts);
  if (!q.ok()) return ToGrpcStatus(q.status());
  resp->set_serial(req->serial());
  resp->set_version(q->version);
  for (int k = 0; k < req->points_size(); ++k) {
    const auto& p = req->points(k);
    const auto& x = q->values[k];
    auto* v = resp->add_values();
    v->set_id_a(p.id_a()); v->set_iq_a(p.iq_a());
    v->set_psi_d_wb(x.psi_d_wb); v->set_psi_q_wb(x.psi_q_wb);
    v->set_ldd_h(x.ldd_h); v->set_lqq_h(x.lqq_h); v->set_ldq_h(x.ldq_h);
    v->set_ld_app_h(x.ld_app_h); v->set_lq_app_h(x.lq_app_h); v->set_torque_nm(x.torque_nm);
    v->set_psi_d_wb_std(x.psi_d_wb_std); v->set_psi_q_wb_std(x.psi_q_wb_std);
    v->set_ldd_h_std(x.ldd_h_std); v->set_lqq_h_std(x.lqq_h_std); v->set_torque_nm_std(x.torque_nm_std);
    v->set_extrapolated(x.extrapolated);
    v->set_region(pipeline::FluxRegionName(x.region));
    v->set_invalid(!x.valid);
    v->set_invalid_reason(x.invalid_reason);
  }
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::ExportTable(grpc::ServerContext* ctx, const v1::ExportTableRequest* req,
                                                 v1::ExportTableResponse* resp) {
  auto who = AdmitForSerial(ctx, Rpc::kExportTable, req->serial());
  if (!who.ok()) return ToGrpcStatus(who.status());
  tables::TableSpec spec;
  spec.kind = req->table().empty() ? "mtpa" : req->table();
  if (req->points() != 0) spec.points = req->points();
  if (req->speed_points() != 0) spec.speed_points = req->speed_points();
  if (req->speed_max_rpm() != 0) spec.speed_max_rpm = req->speed_max_rpm();
  if (auto s = ValidateVersion(req->version()); !s.ok()) return ToGrpcStatus(s);
  if (spec.points < 2 || spec.points > kMaxTablePoints) {
    return ToGrpcStatus(absl::InvalidArgumentError(absl::StrCat("points: must be 2..", kMaxTablePoints)));
  }
  if (spec.speed_points < 2 || spec.speed_points > kMaxTableSpeedPoints) {
    return ToGrpcStatus(absl::InvalidArgumentError(absl::StrCat("speed_points: must be 2..", kMaxTableSpeedPoints)));
  }
  if (spec.kind == "fw" && static_cast<long long>(spec.points) * spec.speed_points > kMaxTableCells) {
    return ToGrpcStatus(absl::ResourceExhaustedError(
        absl::StrCat("points x speed_points: a field-weakening map has at most ", kMaxTableCells, " cells")));
  }
  // A Udc axis: bounded as the CLI's, the maps of all its voltages
  // together no larger than one map may be.
  if (auto s = ValidateUdcAxis(req->udc_axis_v(), req->udc_v(), pipeline::kMaxUdcAxisPoints); !s.ok()) {
    return ToGrpcStatus(s);
  }
  const int axis_points = req->udc_axis_v_size();
  if (spec.kind == "fw" && static_cast<long long>(spec.points) * spec.speed_points * axis_points > kMaxTableCells) {
    return ToGrpcStatus(absl::ResourceExhaustedError(absl::StrCat(
        "points x speed_points x udc_axis_v: the field-weakening maps of a Udc axis have at most ", kMaxTableCells,
        " cells together")));
  }
  spec.envelope_generating = req->generating();
  if (!(spec.speed_max_rpm > 0 && spec.speed_max_rpm <= 1e5)) return ToGrpcStatus(absl::InvalidArgumentError("speed_max_rpm: must be in (0, 100000]"));
  // 0 in a limit field: the calibration's (tables/export_rule.h).
  tables::ExportRequest limits;
  limits.names_flags = false;
  if (!(req->i_max_a() == 0 || (req->i_max_a() > 0 && req->i_max_a() <= 1e4))) {
    return ToGrpcStatus(absl::InvalidArgumentError("i_max_a: must be in (0, 10000] (0: measured limit)"));
  }
  if (!(req->udc_v() == 0 || (req->udc_v() > 0 && req->udc_v() <= 5000))) {
    return ToGrpcStatus(absl::InvalidArgumentError("udc_v: must be in (0, 5000] (0: the calibration's)"));
  }
  if (!(req->rs_ohm() == 0 || (req->rs_ohm() > 0 && req->rs_ohm() <= 1e3))) {
    return ToGrpcStatus(absl::InvalidArgumentError("rs_ohm: must be in (0, 1000] (0: the calibration's)"));
  }
  if (req->i_max_a() != 0) limits.i_max_a = req->i_max_a();
  if (req->udc_v() != 0) limits.udc_v = req->udc_v();
  if (req->rs_ohm() != 0) limits.rs_ohm = req->rs_ohm();
  // Checked (range, the calibration's coefficient and reference) by the
  // export rule, tables::MagnetTemperatureOf, naming magnet_temp_c.
  if (req->has_magnet_temp_c()) limits.magnet_temp_c = req->magnet_temp_c();
  limits.allow_clamped = req->allow_clamped();
  // Flashers get released calibrations only (version 0: the newest
  // released one), re-checked now against verdict and hash chains.
  int version = req->version();
  if (who->role == Role::kFlasher) {
    auto v = pipeline::FlashableVersion(*store_, req->serial(), version);
    if (!v.ok()) return ToGrpcStatus(v.status());
    version = *v;
  }
  spec.allow_extrapolation = req->allow_extrapolation();
  tables::ExportOptions options;
  if (!req->ctype().empty()) {
    auto ct = pipeline::ParseExportCType(req->ctype());
    if (!ct.ok()) return ToGrpcStatus(ct.status());
    options.ctype = *ct;
  }
  const std::string format = req->format().empty() ? "csv" : req->format();
  if (axis_points > 0) {
    // One table per Udc, each in the reply (nothing is written here).
    const std::vector<double> udcs(req->udc_axis_v().begin(), req->udc_axis_v().end());
    auto axis = pipeline::ExportTableOverUdc(*store_, req->serial(), version, spec, limits, udcs, format, options);
    if (!axis.ok()) return ToGrpcStatus(axis.status());
    resp->set_serial(req->serial());
    resp->set_version(axis->version);
    resp->set_verdict(axis->verdict);
    resp->set_released(axis->released);
    int cells = 0, clamped = 0;
    for (const auto& t : axis->tables) {
      const pipeline::ExportResult& r = t.result;
      auto* u = resp->add_udc_tables();
      u->set_udc_v(t.udc_v);
      u->set_file_name(pipeline::ExportFileName(req->serial(), spec, format, t.udc_v));
      u->set_label_tag(r.table.label_tag);
      u->set_data(r.exported.bytes);
      u->set_crc32(absl::StrFormat("%08x", r.exported.payload_crc32));
      u->set_sha256(r.exported.payload_sha256);
      u->set_cells(r.cells);
      u->set_clamped_cells(r.clamped_cells);
      cells += r.cells;
      clamped += r.clamped_cells;
      if (!signing_key_pem_.empty()) {
        auto sig = pipeline::SignExport(r.exported.bytes, signing_key_pem_);
        if (!sig.ok()) return ToGrpcStatus(sig.status());
        u->set_signature(*sig);
      }
    }
    resp->set_cells(cells);
    resp->set_clamped_cells(clamped);
    return grpc::Status::OK;
  }
  auto r = pipeline::ExportTable(*store_, req->serial(), version, spec, limits, format, options);
  if (!r.ok()) return ToGrpcStatus(r.status());
  resp->set_serial(req->serial());
  resp->set_version(r->version);
  resp->set_data(r->exported.bytes);
  resp->set_crc32(absl::StrFormat("%08x", r->exported.payload_crc32));
  resp->set_sha256(r->exported.payload_sha256);
  resp->set_clamped_cells(r->clamped_cells);
  resp->set_cells(r->cells);
  resp->set_verdict(r->verdict);
  resp->set_released(r->released);
  if (!signing_key_pem_.empty()) {
    auto sig = pipeline::SignExport(r->exported.bytes, signing_key_pem_);
    if (!sig.ok()) return ToGrpcStatus(sig.status());
    resp->set_signature(*sig);
  }
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::FleetStatistics(grpc::ServerContext* ctx, const v1::FleetStatisticsRequest* req,
                                                     v1::FleetStatisticsResponse* resp) {
  auto who = Admit(ctx, Rpc::kFleetStatistics);
  if (!who.ok()) return ToGrpcStatus(who.status());
  std::vector<std::pair<double, double>> pts;
  if (req->points_size() > kMaxFleetPoints) {
    return ToGrpcStatus(absl::ResourceExhaustedError(absl::StrCat("points: at most ", kMaxFleetPoints, " per call")));
  }
  if (!std::isfinite(req->outlier_sigma()) || req->outlier_sigma() < 0 || req->outlier_sigma() > 100) {
    return ToGrpcStatus(absl::InvalidArgumentError(absl::StrFormat(
        "outlier_sigma: must be in (0, 100] (0: default 3), got %g", req->outlier_sigma())));
  }
  for (int k = 0; k < req->points_size(); ++k) {
    if (auto s = ValidateOperatingPoint(req->points(k), k); !s.ok()) return ToGrpcStatus(s);
    pts.push_back({req->points(k).id_a(), req->points(k).iq_a()});
  }
  if (pts.empty()) pts.assign(std::begin(pipeline::kDefaultFleetPointsA), std::end(pipeline::kDefaultFleetPointsA));
  const double sigma = req->outlier_sigma() > 0 ? req->outlier_sigma() : pipeline::kDefaultOutlierSigma;
  auto stats = pipeline::FleetStatistics(*store_, pts, sigma, CancelledBy(ctx));
  if (!stats.ok()) return StoppedOr(ctx, stats.status());
  for (const auto& s : *stats) {
    auto* p = resp->add_points();
    p->set_id_a(s.id_a); p->set_iq_a(s.iq_a); p->set_serials(s.serials);
    p->set_ldd_h_mean(s.ldd_h_mean); p->set_ldd_h_std(s.ldd_h_std);
    p->set_lqq_h_mean(s.lqq_h_mean); p->set_lqq_h_std(s.lqq_h_std);
    p->set_psi_d_wb_mean(s.psi_d_wb_mean); p->set_psi_d_wb_std(s.psi_d_wb_std);
    p->set_torque_nm_mean(s.torque_nm_mean); p->set_torque_nm_std(s.torque_nm_std);
    for (const auto& o : s.outliers) p->add_outliers(o);
  }
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::Audit(grpc::ServerContext* ctx, const v1::AuditRequest* req,
                                           v1::AuditResponse* resp) {
  auto who = AdmitForSerial(ctx, Rpc::kAudit, req->serial());
  if (!who.ok()) return ToGrpcStatus(who.status());
  auto rows = pipeline::AuditTrail(*store_, req->serial());
  if (!rows.ok()) return ToGrpcStatus(rows.status());
  resp->set_serial(req->serial());
  for (const auto& r : *rows) {
    auto* e = resp->add_entries();
    e->set_id(r.id); e->set_utc(r.utc); e->set_identity(r.identity); e->set_role(r.role); e->set_peer(r.peer);
    e->set_request_id(r.request_id); e->set_rpc(r.rpc); e->set_detail(r.detail);
  }
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::GetReport(grpc::ServerContext* ctx, const v1::GetReportRequest* req,
                                               v1::GetReportResponse* resp) {
  auto who = AdmitForSerial(ctx, Rpc::kGetReport, req->serial());
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateVersion(req->version()); !s.ok()) return ToGrpcStatus(s);
  if (auto s = ValidateDefaultable("speed_rpm", req->speed_rpm(), kMaxSpeedRpm, "rpm"); !s.ok()) return ToGrpcStatus(s);
  if (auto s = ValidateDefaultable("udc_v", req->udc_v(), kMaxUdcV, "V"); !s.ok()) return ToGrpcStatus(s);
  pipeline::StoredReportOptions options;
  options.speed_rpm = req->speed_rpm();
  options.udc_v = req->udc_v();
  // The fleet section names other serials (its outliers): only for a role
  // that may read fleet statistics anyway.
  options.include_fleet =
      (!req->has_include_fleet() || req->include_fleet()) && RoleMayCall(who->role, Rpc::kFleetStatistics);
  auto rep = pipeline::BuildStoredReport(*store_, req->serial(), req->version(), options, CancelledBy(ctx));
  if (!rep.ok()) return StoppedOr(ctx, rep.status());
  if (rep->page.html.size() > kMaxReportBytes) {
    return ToGrpcStatus(absl::ResourceExhaustedError(absl::StrCat(
        "html: the page of ", req->serial(), " version ", rep->version, " has ", rep->page.html.size(),
        " bytes, above the limit of ", kMaxReportBytes)));
  }
  resp->set_html(rep->page.html);
  resp->set_serial(rep->serial);
  resp->set_version(rep->version);
  resp->set_verdict(rep->verdict);
  resp->set_figures(rep->page.figures);
  resp->set_html_sha256(rep->html_sha256);
  resp->set_voltage_limit_speed_rpm(rep->page.ellipse_speed_rpm);
  resp->set_fleet_included(rep->fleet_included);
  return grpc::Status::OK;
}

}  // namespace fluxcal::server
