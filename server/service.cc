#include "server/service.h"

#include <cmath>

#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/support/server_interceptor.h>

#include <chrono>
#include <cstdio>
#include <iterator>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/csv.h"
#include "io/net.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "pipeline/anchor.h"
#include "pipeline/diagnose.h"
#include "pipeline/ingest_stream.h"
#include "pipeline/pipeline.h"
#include "pipeline/report.h"
#include "pipeline/signing.h"
#include "server/reflection.h"
#include "server/validation.h"

namespace fluxcal::server {

namespace {

// The client's deadline and cancellation as a plain callback for the
// pipeline's long loops (the libraries know nothing of gRPC).
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

}  // namespace

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

// Read() returned false before the stream's end message: either the client
// closed its side, or the message at `next` failed to parse (gRPC ends the
// reads at a message it cannot parse, whatever follows it). One more Read
// tells the two apart when a message follows the broken one; a stream that
// declared its end (end_follows) is refused either way.
template <class Message>
grpc::Status EndedWithoutEnd(grpc::ServerReader<Message>* reader, Message* scratch, int64_t next, bool end_follows,
                             const std::string& chunks = "") {
  auto at = [&](const std::string& why) {
    if (chunks.empty()) return AtMessage(next, absl::InvalidArgumentError(why));
    return ToGrpcStatus(absl::InvalidArgumentError(absl::StrCat(chunks, "[", next, "]: ", why, "; nothing stored")));
  };
  if (reader->Read(scratch)) {
    return at(absl::StrCat("failed to parse as ", Message::descriptor()->full_name(),
                           " (corrupt, or another message); the stream went on after it"));
  }
  if (end_follows) {
    return at("end: the stream ended without its end message (declared by end_follows): a message failed to "
              "parse or the stream was cut");
  }
  return grpc::Status::OK;
}

}  // namespace

grpc::Status CalibrationServiceImpl::IngestHfResults(grpc::ServerContext* ctx,
                                                     grpc::ServerReader<v1::IngestHfResultsRequest>* reader,
                                                     v1::IngestHfResultsResponse* response) {
  auto who = Admit(ctx, Rpc::kIngestHfResults);
  if (!who.ok()) return ToGrpcStatus(who.status());
  // Stream rules (docs/service.md): any bad message fails the whole stream
  // with the message's index, and nothing is stored.
  v1::IngestHfResultsRequest msg;
  std::string serial, station, key;
  v1::MotorInfo motor;
  bool have_motor = false, end_follows = false;
  std::optional<v1::StreamEnd> end;
  int64_t end_message = -1;
  std::vector<pipeline::IdentifiedPoint> rows;
  std::set<std::string> point_ids;
  int index = 0;
  int64_t messages = 0;
  while (reader->Read(&msg)) {
    if (auto s = who->lease.Add(static_cast<int64_t>(msg.ByteSizeLong())); !s.ok()) return ToGrpcStatus(s);
    if (ctx->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "client cancelled the stream");
    const int64_t m = messages++;
    if (end) {
      return AtMessage(m, absl::InvalidArgumentError(
                              absl::StrCat("end: a message after the stream's end (message ", end_message, ")")));
    }
    if (m == 0) {
      if (auto s = ValidateSerial(msg.serial()); !s.ok()) return AtMessage(m, s);
      if (auto s = ValidateIdentifier(msg.station_id(), "station_id"); !s.ok()) return AtMessage(m, s);
      if (auto s = StationOf(*who, msg.station_id(), &station); !s.ok()) return AtMessage(m, s);
      if (auto s = ValidateIdentifier(msg.idempotency_key(), "idempotency_key"); !s.ok()) return AtMessage(m, s);
      key = msg.idempotency_key();
      serial = msg.serial();
      end_follows = msg.end_follows();
    } else if (!msg.serial().empty() && msg.serial() != serial) {
      return AtMessage(m, absl::InvalidArgumentError(absl::StrCat(
                              "serial: a stream carries one serial; got '", io::Printable(msg.serial().substr(0, 80)),
                              "' after '", serial, "'")));
    } else if (msg.end_follows()) {
      return AtMessage(m, absl::InvalidArgumentError("end_follows: only the first message declares the end"));
    }
    if (msg.has_motor()) {
      if (auto s = ValidateMotor(msg.motor()); !s.ok()) return AtMessage(m, s);
      motor = msg.motor();
      have_motor = true;
    }
    for (const auto& p : msg.points()) {
      if (index >= kMaxPointsPerStream) {
        return AtMessage(m, absl::ResourceExhaustedError(
                                absl::StrCat("points: stream exceeds the limit of ", kMaxPointsPerStream, " points")));
      }
      absl::Status s = ValidatePoint(p, index);
      if (s.ok() && !p.point_id().empty() && !point_ids.insert(p.point_id()).second) {
        s = absl::InvalidArgumentError(absl::StrCat("points[", index, "].point_id: duplicate '",
                                                    io::Printable(p.point_id().substr(0, kMaxIdentifierBytes)), "'"));
      }
      if (!s.ok()) return AtMessage(m, s);
      rows.push_back(pipeline::FromProto(p));
      ++index;
    }
    if (msg.has_end()) {
      if (!end_follows) {
        return AtMessage(m, absl::InvalidArgumentError("end: the first message did not declare end_follows"));
      }
      if (auto s = ValidateStreamEnd(msg.end(), "end"); !s.ok()) return AtMessage(m, s);
      end = msg.end();
      end_message = m;
    }
  }
  if (ctx->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "client cancelled the stream");
  if (!end) {
    if (auto s = EndedWithoutEnd(reader, &msg, messages, end_follows); !s.ok()) return s;
  }
  if (serial.empty()) return AtMessage(0, absl::InvalidArgumentError("serial: the stream carried no message"));
  if (end) {
    const pipeline::StreamTotals declared{end->messages(), end->count(), end->bytes(), end->sha256()};
    const pipeline::StreamTotals received{messages, static_cast<int64_t>(rows.size()), 0,
                                          pipeline::HfPointsSha256(rows)};
    if (auto s = pipeline::CheckStreamEnd(declared, received, "end", "points"); !s.ok()) return AtMessage(end_message, s);
  }
  if (auto s = pipeline::CheckDistinctOperatingPoints(rows); !s.ok()) return ToGrpcStatus(s);
  std::optional<pipeline::MotorNominal> m;
  if (have_motor) m = pipeline::MotorNominal{motor.pole_pairs(), motor.rs_ohm(), motor.psi_pm_wb()};
  bool replayed = false;
  const size_t n = rows.size();
  const auto audit = AuditFor(ctx, *who, Rpc::kIngestHfResults, serial, [n, station](int64_t run, bool again) {
    return absl::StrCat(again ? "replayed run " : "run ", run, ", ", n, " points, station ", station);
  });
  auto run = pipeline::IngestHfRun(*store_, serial, station, m, rows, 0, key, &replayed, &audit);
  if (!run.ok()) return ToGrpcStatus(run.status());
  // What was accepted and stored (for a replay: the run stored before): the
  // client compares it with what it sent.
  auto stored = pipeline::DigestOfIngest(*store_, *run, replayed, rows);
  if (!stored.ok()) return ToGrpcStatus(stored.status());
  response->set_serial(serial);
  response->set_run_id(*run);
  response->set_accepted(static_cast<int>(stored->points));
  response->set_points_sha256(stored->points_sha256);
  response->set_replayed(replayed);
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::IngestRecording(grpc::ServerContext* ctx,
                                                     grpc::ServerReader<v1::RecordingChunk>* reader,
                                                     v1::IngestRecordingResponse* response) {
  auto who = Admit(ctx, Rpc::kIngestRecording);
  if (!who.ok()) return ToGrpcStatus(who.status());
  // The set is assembled, validated and identified in memory: a file name
  // from the client never becomes a path on this machine. Stream rules as
  // IngestHfResults; a chunk's field names say its index.
  v1::RecordingChunk chunk;
  std::string serial, station, key;
  io::RecordingFiles files;
  bool end_follows = false;
  std::optional<v1::StreamEnd> end;
  std::string end_field;
  long long total = 0;
  int64_t index = 0;
  while (reader->Read(&chunk)) {
    if (ctx->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "client cancelled the stream");
    if (auto s = who->lease.Add(static_cast<int64_t>(chunk.ByteSizeLong())); !s.ok()) return ToGrpcStatus(s);
    const std::string field = absl::StrCat("chunks[", index++, "]");
    if (end) {
      return ToGrpcStatus(absl::InvalidArgumentError(
          absl::StrCat(field, ": a chunk after the stream's end (", end_field, "); nothing stored")));
    }
    if (serial.empty()) {
      if (auto s = ValidateSerial(chunk.serial(), field + ".serial"); !s.ok()) return ToGrpcStatus(s);
      if (auto s = ValidateIdentifier(chunk.station_id(), field + ".station_id"); !s.ok()) return ToGrpcStatus(s);
      if (auto s = StationOf(*who, chunk.station_id(), &station); !s.ok()) return ToGrpcStatus(s);
      if (auto s = ValidateIdentifier(chunk.idempotency_key(), field + ".idempotency_key"); !s.ok()) {
        return ToGrpcStatus(s);
      }
      key = chunk.idempotency_key();
      serial = chunk.serial();
      end_follows = chunk.end_follows();
    } else if (!chunk.serial().empty() && chunk.serial() != serial) {
      return ToGrpcStatus(absl::InvalidArgumentError(
          absl::StrCat(field, ".serial: a stream carries one serial; got '", io::Printable(chunk.serial().substr(0, 80)),
                       "' after '", serial, "'")));
    } else if (chunk.end_follows()) {
      return ToGrpcStatus(absl::InvalidArgumentError(
          absl::StrCat(field, ".end_follows: only the first chunk declares the end")));
    }
    if (chunk.has_end()) {
      if (!end_follows) {
        return ToGrpcStatus(absl::InvalidArgumentError(
            absl::StrCat(field, ".end: the first chunk did not declare end_follows")));
      }
      if (auto s = ValidateStreamEnd(chunk.end(), field + ".end"); !s.ok()) return ToGrpcStatus(s);
      end = chunk.end();
      end_field = field + ".end";
      if (chunk.path().empty() && chunk.data().empty()) continue;   // an end-only chunk
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
  if (ctx->IsCancelled()) return grpc::Status(grpc::StatusCode::CANCELLED, "client cancelled the stream");
  if (!end) {
    if (auto s = EndedWithoutEnd(reader, &chunk, index, end_follows, "chunks"); !s.ok()) return s;
  }
  if (serial.empty()) return ToGrpcStatus(absl::InvalidArgumentError("serial: the stream carried no chunk"));
  if (end) {
    const pipeline::StreamTotals declared{end->messages(), end->count(), end->bytes(), end->sha256()};
    const pipeline::StreamTotals received{index, static_cast<int64_t>(files.size()), pipeline::RecordingFilesBytes(files),
                                          pipeline::RecordingFilesSha256(files)};
    if (auto s = pipeline::CheckStreamEnd(declared, received, end_field, "files"); !s.ok()) return ToGrpcStatus(s);
  }
  // The detail names the recording, known only after identification: the
  // store calls this inside the transaction, by then `sha` is set.
  std::string sha;
  const auto audit = AuditFor(ctx, *who, Rpc::kIngestRecording, serial, [&sha, station](int64_t run, bool again) {
    return absl::StrCat(again ? "replayed run " : "run ", run, ", recording ", sha.substr(0, 16), ", station ", station);
  });
  auto run = pipeline::IngestRecording(*store_, serial, station, files, key, &audit, CancelledBy(ctx), &sha);
  if (!run.ok()) return StoppedOr(ctx, run.status());
  response->set_serial(serial);
  response->set_run_id(run->run_id);
  response->set_points(run->points);
  response->set_recording_sha256(run->sha256);
  response->set_recording_bytes(run->recording_bytes);
  response->set_stored_bytes(run->stored_bytes);
  response->set_replayed(run->replayed);
  response->set_points_sha256(run->points_sha256);
  response->set_files(run->files);
  response->set_files_bytes(run->files_bytes);
  response->set_files_sha256(run->files_sha256);
  return grpc::Status::OK;
}

grpc::Status CalibrationServiceImpl::Fit(grpc::ServerContext* ctx, const v1::FitRequest* req, v1::FitResponse* resp) {
  auto who = Admit(ctx, Rpc::kFit);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
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

grpc::Status CalibrationServiceImpl::GetCalibration(grpc::ServerContext* ctx, const v1::GetCalibrationRequest* req,
                                                    v1::CalibrationRecord* resp) {
  auto who = Admit(ctx, Rpc::kGetCalibration);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
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
  auto who = Admit(ctx, Rpc::kHistory);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
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
  auto who = Admit(ctx, Rpc::kQueryFlux);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
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
  auto who = Admit(ctx, Rpc::kExportTable);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
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
  auto r = pipeline::ExportTable(*store_, req->serial(), version, spec, limits,
                                req->format().empty() ? "csv" : req->format(), options);
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

grpc::Status CalibrationServiceImpl::Diagnose(grpc::ServerContext* ctx, const v1::DiagnoseRequest* req,
                                              v1::DiagnoseResponse* resp) {
  auto who = Admit(ctx, Rpc::kDiagnose);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
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
  auto who = Admit(ctx, Rpc::kRelease);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
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

grpc::Status CalibrationServiceImpl::Audit(grpc::ServerContext* ctx, const v1::AuditRequest* req,
                                           v1::AuditResponse* resp) {
  auto who = Admit(ctx, Rpc::kAudit);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
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
  auto who = Admit(ctx, Rpc::kGetReport);
  if (!who.ok()) return ToGrpcStatus(who.status());
  if (auto s = ValidateSerial(req->serial()); !s.ok()) return ToGrpcStatus(s);
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

namespace {

// One stderr line per request: method, identity, peer, status, latency.
class RequestLog final : public grpc::experimental::Interceptor {
 public:
  RequestLog(grpc::experimental::ServerRpcInfo* info, const Authorizer* auth)
      : info_(info), auth_(auth), start_(std::chrono::steady_clock::now()) {}
  void Intercept(grpc::experimental::InterceptorBatchMethods* m) override {
    if (m->QueryInterceptionHookPoint(grpc::experimental::InterceptionHookPoints::PRE_SEND_STATUS)) {
      const grpc::Status st = m->GetSendStatus();
      const grpc::ServerContextBase* base = info_->server_context();
      std::string who = "-", peer = "-";
      if (const auto* ctx = dynamic_cast<const grpc::ServerContext*>(base)) {
        if (auto id = auth_->Authenticate(*ctx); id.ok()) who = absl::StrCat(id->name, "/", std::string(RoleName(id->role)));
        peer = ctx->peer();
      }
      const double ms =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_).count();
      std::fprintf(stderr, "fluxcal serve: rpc=%s identity=%s peer=%s status=%d latency_ms=%.1f\n", info_->method(),
                   who.c_str(), peer.c_str(), static_cast<int>(st.error_code()), ms);
    }
    m->Proceed();
  }

 private:
  grpc::experimental::ServerRpcInfo* info_;
  const Authorizer* auth_;
  std::chrono::steady_clock::time_point start_;
};

class RequestLogFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit RequestLogFactory(const Authorizer* auth) : auth_(auth) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo* info) override {
    return new RequestLog(info, auth_);
  }

 private:
  const Authorizer* auth_;
};

}  // namespace

std::unique_ptr<grpc::Server> StartServer(CalibrationServiceImpl* service, const std::string& address,
                                          int* bound_port, const ServerOptions& options) {
  grpc::EnableDefaultHealthCheckService(true);
  ReturnLargeBlocksWhenFreed();
  grpc::ServerBuilder b;
  const Authorizer* auth = service->authorizer();
  std::shared_ptr<grpc::ServerCredentials> creds;
  bool takes_processor = true;
  if (!options.tls_cert_pem.empty()) {
    grpc::SslServerCredentialsOptions ssl(
        options.client_ca_pem.empty() ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
        : options.require_client_cert ? GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY
                                      : GRPC_SSL_REQUEST_CLIENT_CERTIFICATE_AND_VERIFY);
    ssl.pem_root_certs = options.client_ca_pem;
    ssl.pem_key_cert_pairs.push_back({options.tls_key_pem, options.tls_cert_pem});
    creds = grpc::SslServerCredentials(ssl);
  } else if (!auth->open() && io::IsLoopbackAddress(address)) {
    // Plaintext on the wire as before, but gRPC's local credentials take an
    // AuthMetadataProcessor (its insecure ones do not) and refuse peers
    // that are not on this machine.
    creds = grpc::experimental::LocalServerCredentials(address.rfind("unix", 0) == 0 ? UDS : LOCAL_TCP);
  } else {
    creds = grpc::InsecureServerCredentials();
    takes_processor = false;
  }
  if (!auth->open() && takes_processor) {
    Authorizer::LogFn log;
    if (options.log_requests) log = [](const std::string& m) { std::fprintf(stderr, "fluxcal serve: %s\n", m.c_str()); };
    creds->SetAuthMetadataProcessor(MakeAuthProcessor(auth, std::move(log)));
  }
  // No SO_REUSEPORT (gRPC's default on Linux): a second `fluxcal serve` on
  // a port already in use must fail to start, not silently take half of
  // the connections to its own store.
  b.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  // HTTP/2 flow control without BDP probing: a stream's window stays at
  // 64 KiB ahead of what its handler reads (the handler's read of a message
  // opens the window for that message). With probing, gRPC grows windows
  // to megabytes, and a whole unauthenticated message reached the server
  // before the call was refused (measured: tests/server/ops_test, PreAuth).
  b.AddChannelArgument(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  b.AddListeningPort(address, creds, bound_port);
  b.RegisterService(service);
  if (options.reflection) {
    auto refl = MakeReflectionServices(service->authorizer(),
                                       {v1::CalibrationService::service_full_name(), "grpc.health.v1.Health"});
    for (auto& r : refl) {
      b.RegisterService(r.get());
      service->KeepAlive(std::move(r));
    }
  }
  // Small messages: no legitimate request is larger (server/limits.h).
  b.SetMaxReceiveMessageSize(kMaxMessageBytes);
  if (options.log_requests) {
    static const Authorizer kOpen;
    std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> creators;
    creators.push_back(std::make_unique<RequestLogFactory>(options.authorizer ? options.authorizer : &kOpen));
    b.experimental().SetInterceptorCreators(std::move(creators));
  }
  return b.BuildAndStart();
}

}  // namespace fluxcal::server
