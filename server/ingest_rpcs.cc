// The streaming RPCs that bring runs in: HF results and raw recordings,
// each stream checked message by message (nothing stored on any error)
// and against its declared end.
#include "server/service.h"

#include <grpcpp/grpcpp.h>

#include "absl/strings/str_cat.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "pipeline/ingest_stream.h"
#include "pipeline/pipeline.h"
#include "server/internal.h"
#include "server/validation.h"

namespace fluxcal::server {

using internal::AtMessage;
using internal::CancelledBy;
using internal::EndedWithoutEnd;
using internal::StationOf;
using internal::StoppedOr;

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

}  // namespace fluxcal::server
