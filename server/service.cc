#include "server/service.h"

#include <cmath>

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/grpcpp.h>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "pipeline/pipeline.h"
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
    default: break;
  }
  return grpc::Status(c, std::string(s.message()));
}

namespace {

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

}  // namespace

grpc::Status CalibrationServiceImpl::IngestHfResults(grpc::ServerContext* ctx,
                                                     grpc::ServerReader<v1::IngestHfResultsRequest>* reader,
                                                     v1::IngestHfResultsResponse* response) {
  v1::IngestHfResultsRequest msg;
  std::string serial, station;
  v1::MotorInfo motor;
  bool have_motor = false;
  std::vector<pipeline::IdentifiedPoint> rows;
  int index = 0;
  while (reader->Read(&msg)) {
    if (ctx->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "client cancelled the stream");
    if (serial.empty()) {
      if (auto s = ValidateSerial(msg.serial()); !s.ok()) return ToGrpcStatus(s);
      if (auto s = ValidateIdentifier(msg.station_id(), "station_id"); !s.ok()) return ToGrpcStatus(s);
      serial = msg.serial();
      station = msg.station_id();
    } else if (!msg.serial().empty() && msg.serial() != serial) {
      return ToGrpcStatus(absl::InvalidArgumentError(
          absl::StrCat("serial: a stream carries one serial; got '", io::Printable(msg.serial().substr(0, 80)), "' after '",
                       serial, "'")));
    }
    if (msg.has_motor()) {
      if (auto s = ValidateMotor(msg.motor()); !s.ok()) return ToGrpcStatus(s);
      motor = msg.motor();
      have_motor = true;
    }
    for (const auto& p : msg.points()) {
      if (index >= kMaxPointsPerStream) {
        return ToGrpcStatus(absl::InvalidArgumentError(
            absl::StrCat("points: stream exceeds ", kMaxPointsPerStream, " points")));
      }
      if (auto s = ValidatePoint(p, index); !s.ok()) {
        auto* r = response->add_rejects();
        r->set_index(index);
        r->set_point_id(io::Printable(p.point_id().substr(0, kMaxIdentifierBytes)));
        const std::string m(s.message());
        r->set_field(m.substr(0, m.find(':')));
        r->set_message(m);
      } else {
        rows.push_back(pipeline::FromProto(p));
      }
      ++index;
    }
  }
  if (serial.empty()) return ToGrpcStatus(absl::InvalidArgumentError("serial: the stream carried no message"));
  if (ctx->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "client cancelled the stream");
  std::optional<pipeline::MotorNominal> m;
  if (have_motor) m = pipeline::MotorNominal{motor.pole_pairs(), motor.rs_ohm(), motor.psi_pm_wb()};
  auto run = pipeline::IngestHfRun(*store_, serial, station, m, rows, response->rejects_size());
  if (!run.ok()) return ToGrpcStatus(run.status());
  response->set_serial(serial);
  response->set_run_id(*run);
  response->set_accepted(static_cast<int>(rows.size()));
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::IngestRecording(grpc::ServerContext* ctx,
                                                     grpc::ServerReader<v1::RecordingChunk>* reader,
                                                     v1::IngestRecordingResponse* response) {
  // The set is assembled, validated and identified in memory: a file name
  // from the client never becomes a path on this machine.
  v1::RecordingChunk chunk;
  std::string serial, station;
  io::RecordingFiles files;
  long long total = 0;
  int index = 0;
  while (reader->Read(&chunk)) {
    const std::string field = absl::StrCat("chunks[", index++, "]");
    if (serial.empty()) {
      if (auto s = ValidateSerial(chunk.serial(), field + ".serial"); !s.ok()) return ToGrpcStatus(s);
      if (auto s = ValidateIdentifier(chunk.station_id(), field + ".station_id"); !s.ok()) return ToGrpcStatus(s);
      serial = chunk.serial();
      station = chunk.station_id();
    } else if (!chunk.serial().empty() && chunk.serial() != serial) {
      return ToGrpcStatus(absl::InvalidArgumentError(
          absl::StrCat(field, ".serial: a stream carries one serial; got '", io::Printable(chunk.serial().substr(0, 80)),
                       "' after '", serial, "'")));
    }
    if (auto s = io::ValidateRecordingFileName(chunk.path()); !s.ok()) {
      return ToGrpcStatus(absl::InvalidArgumentError(absl::StrCat(field, ".path: ", s.message())));
    }
    total += static_cast<long long>(chunk.data().size());
    if (total > kMaxRecordingBytes) {
      return ToGrpcStatus(absl::ResourceExhaustedError(
          absl::StrCat(field, ".data: recording exceeds the limit of ", kMaxRecordingBytes, " bytes")));
    }
    auto it = files.find(chunk.path());
    if (it == files.end()) {
      if (static_cast<int>(files.size()) >= kMaxRecordingFiles) {
        return ToGrpcStatus(absl::ResourceExhaustedError(
            absl::StrCat(field, ".path: recording exceeds the limit of ", kMaxRecordingFiles, " files")));
      }
      it = files.emplace(chunk.path(), std::string()).first;
    }
    it->second += chunk.data();
  }
  if (serial.empty()) return ToGrpcStatus(absl::InvalidArgumentError("serial: the stream carried no chunk"));
  if (ctx->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "client cancelled the stream");
  auto run = pipeline::IngestRecording(*store_, serial, station, files);
  if (!run.ok()) return ToGrpcStatus(run.status());
  response->set_serial(serial);
  response->set_run_id(run->run_id);
  response->set_points(run->points);
  response->set_recording_sha256(run->sha256);
  response->set_recording_bytes(run->recording_bytes);
  response->set_stored_bytes(run->stored_bytes);
  return grpc::Status::OK;
}
grpc::Status CalibrationServiceImpl::Fit(grpc::ServerContext*, const v1::FitRequest* req, v1::FitResponse* resp) {
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
  pipeline::FitTolerances tol;
  if (req->max_rms_relative() < 0 || !std::isfinite(req->max_rms_relative()) ||
      req->psi_pm_tolerance_relative() < 0 || !std::isfinite(req->psi_pm_tolerance_relative())) {
    return ToGrpcStatus(absl::InvalidArgumentError("max_rms_relative, psi_pm_tolerance_relative: must be >= 0"));
  }
  if (req->max_rms_relative() > 0) tol.max_rms_relative = req->max_rms_relative();
  if (req->psi_pm_tolerance_relative() > 0) tol.psi_pm_tolerance_relative = req->psi_pm_tolerance_relative();
  auto row = pipeline::FitSerial(*store_, req->serial(), req->model(), tol);
  if (!row.ok()) return ToGrpcStatus(row.status());
  ToProto(*row, resp->mutable_calibration());
  resp->set_pass(row->verdict == "pass");
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::GetCalibration(grpc::ServerContext*, const v1::GetCalibrationRequest* req,
                                                    v1::CalibrationRecord* resp) {
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
  if (req->version() < 0) return ToGrpcStatus(absl::InvalidArgumentError("version: must be >= 0 (0 = latest)"));
  auto row = store_->GetCalibration(req->serial(), req->version());
  if (!row.ok()) return ToGrpcStatus(row.status());
  ToProto(*row, resp);
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::ListMotors(grpc::ServerContext*, const v1::ListMotorsRequest* req,
                                                v1::ListMotorsResponse* resp) {
  int size = req->page_size() == 0 ? 50 : req->page_size();
  if (size < 0 || size > 1000) return ToGrpcStatus(absl::InvalidArgumentError("page_size: must be 0..1000"));
  int offset = 0;
  if (!req->page_token().empty()) {
    try {
      offset = std::stoi(req->page_token());
    } catch (...) {
      offset = -1;
    }
    if (offset < 0) return ToGrpcStatus(absl::InvalidArgumentError("page_token: not a token from this service"));
  }
  auto rows = store_->ListMotors(req->serial_prefix(), req->only_failed(), offset, size + 1);
  if (!rows.ok()) return ToGrpcStatus(rows.status());
  for (size_t k = 0; k < rows->size() && static_cast<int>(k) < size; ++k) {
    auto* m = resp->add_motors();
    const auto& r = (*rows)[k];
    m->set_serial(r.serial); m->set_latest_version(r.latest_version); m->set_verdict(r.verdict);
    m->set_runs(r.runs); m->set_updated_utc(r.updated_utc);
  }
  if (static_cast<int>(rows->size()) > size) resp->set_next_page_token(std::to_string(offset + size));
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::History(grpc::ServerContext*, const v1::HistoryRequest* req,
                                             v1::HistoryResponse* resp) {
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
  auto rows = store_->History(req->serial());
  if (!rows.ok()) return ToGrpcStatus(rows.status());
  resp->set_serial(req->serial());
  for (const auto& r : *rows) {
    auto* e = resp->add_events();
    e->set_created_utc(r.created_utc); e->set_kind(r.kind); e->set_run_id(r.run_id);
    e->set_version(r.version); e->set_detail(r.detail);
  }
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::QueryFlux(grpc::ServerContext*, const v1::QueryFluxRequest* req,
                                               v1::QueryFluxResponse* resp) {
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
  if (req->points_size() > 100000) return ToGrpcStatus(absl::InvalidArgumentError("points: at most 100000 per call"));
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
  }
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::ExportTable(grpc::ServerContext*, const v1::ExportTableRequest* req,
                                                 v1::ExportTableResponse* resp) {
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
  tables::TableSpec spec;
  spec.kind = req->table().empty() ? "mtpa" : req->table();
  if (req->points() != 0) spec.points = req->points();
  if (req->speed_points() != 0) spec.speed_points = req->speed_points();
  if (req->speed_max_rpm() != 0) spec.speed_max_rpm = req->speed_max_rpm();
  if (spec.points < 2 || spec.points > 4096) return ToGrpcStatus(absl::InvalidArgumentError("points: must be 2..4096"));
  if (spec.speed_points < 2 || spec.speed_points > 1024) return ToGrpcStatus(absl::InvalidArgumentError("speed_points: must be 2..1024"));
  if (!(spec.speed_max_rpm > 0 && spec.speed_max_rpm <= 1e5)) return ToGrpcStatus(absl::InvalidArgumentError("speed_max_rpm: must be in (0, 100000]"));
  tables::MachineLimits lim;
  lim.i_max_a = req->i_max_a();   // 0: the calibration's measured current limit
  if (lim.i_max_a == 0) lim.i_max_a = -1;
  if (req->udc_v() != 0) lim.udc_v = req->udc_v();
  if (!(lim.i_max_a == -1 || (lim.i_max_a > 0 && lim.i_max_a <= 1e4))) {
    return ToGrpcStatus(absl::InvalidArgumentError("i_max_a: must be in (0, 10000] (0: measured limit)"));
  }
  if (!(lim.udc_v > 0 && lim.udc_v <= 5000)) return ToGrpcStatus(absl::InvalidArgumentError("udc_v: must be in (0, 5000]"));
  auto r = pipeline::ExportTable(*store_, req->serial(), req->version(), spec, lim,
                                req->format().empty() ? "csv" : req->format());
  if (!r.ok()) return ToGrpcStatus(r.status());
  resp->set_serial(req->serial());
  resp->set_version(r->version);
  resp->set_data(r->exported.bytes);
  resp->set_crc32(absl::StrFormat("%08x", r->exported.crc32));
  resp->set_sha256(r->exported.sha256);
  resp->set_clamped_cells(r->clamped_cells);
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::FleetStatistics(grpc::ServerContext*, const v1::FleetStatisticsRequest* req,
                                                     v1::FleetStatisticsResponse* resp) {
  std::vector<std::pair<double, double>> pts;
  for (int k = 0; k < req->points_size(); ++k) {
    if (auto s = ValidateOperatingPoint(req->points(k), k); !s.ok()) return ToGrpcStatus(s);
    pts.push_back({req->points(k).id_a(), req->points(k).iq_a()});
  }
  if (pts.empty()) pts = {{-20, 40}, {-60, 80}, {0, 100}};
  const double sigma = req->outlier_sigma() > 0 ? req->outlier_sigma() : 3.0;
  auto stats = pipeline::FleetStatistics(*store_, pts, sigma);
  if (!stats.ok()) return ToGrpcStatus(stats.status());
  for (const auto& s : *stats) {
    auto* p = resp->add_points();
    p->set_id_a(s.id_a); p->set_iq_a(s.iq_a); p->set_serials(s.serials);
    p->set_ldd_h_mean(s.ldd_mean); p->set_ldd_h_std(s.ldd_std);
    p->set_lqq_h_mean(s.lqq_mean); p->set_lqq_h_std(s.lqq_std);
    p->set_psi_d_wb_mean(s.psi_d_mean); p->set_psi_d_wb_std(s.psi_d_std);
    p->set_torque_nm_mean(s.torque_mean); p->set_torque_nm_std(s.torque_std);
    for (const auto& o : s.outliers) p->add_outliers(o);
  }
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::Diagnose(grpc::ServerContext*, const v1::DiagnoseRequest* req,
                                              v1::DiagnoseResponse* resp) {
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
  auto rep = pipeline::DiagnoseStored(*store_, req->serial());
  if (!rep.ok()) return ToGrpcStatus(rep.status());
  resp->set_serial(req->serial());
  resp->set_verdict(rep->verdict);
  resp->set_report_json(diag::ToJson(*rep).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
  for (const auto& f : rep->findings) resp->add_effects(f.effect);
  return grpc::Status::OK;
}

std::unique_ptr<grpc::Server> StartServer(CalibrationServiceImpl* service, const std::string& address,
                                          int* bound_port) {
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder b;
  b.AddListeningPort(address, grpc::InsecureServerCredentials(), bound_port);
  b.RegisterService(service);
  b.SetMaxReceiveMessageSize(64 << 20);
  return b.BuildAndStart();
}

}  // namespace fluxcal::server
