#include "pipeline/eol_station.h"

#include <chrono>
#include <filesystem>
#include <thread>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/csv.h"
#include "io/sha256.h"
#include "pipeline/ingest_stream.h"
#include "pipeline/points.h"

namespace fluxcal::pipeline {
namespace {

// The files of a set as IngestRecording wants them: manifest.json and
// every file the manifest names (the service refuses any other), under
// normalised relative names, with the bytes as on disk.
absl::StatusOr<io::RecordingFiles> SetFiles(const std::string& dir, const io::Manifest& m) {
  auto norm = [](const std::string& f) { return std::filesystem::path(f).lexically_normal().generic_string(); };
  std::vector<std::string> names = {"manifest.json"};
  for (const auto& p : m.points) names.push_back(norm(p.file));
  if (m.steady_state) names.push_back(norm(*m.steady_state));
  if (m.hf_results) names.push_back(norm(*m.hf_results));
  io::RecordingFiles files;
  for (const auto& name : names) {
    if (files.count(name)) continue;
    auto data = io::ReadFileToString((std::filesystem::path(dir) / name).string());
    if (!data.ok()) return data.status();
    files.emplace(name, std::move(*data));
  }
  return files;
}

// UNAVAILABLE and DEADLINE_EXCEEDED may hide a reply that was lost after
// the server stored the run: `attempt` is repeated (3 tries in all) with
// the same idempotency key, so the retry stores nothing twice.
template <class F>
grpc::Status WithRetries(const std::string& serial, const char* what, const EolStationOptions& o, F attempt) {
  grpc::Status s;
  for (int k = 0; k < 3; ++k) {
    if (k > 0) {
      if (o.log) {
        o.log(absl::StrFormat("eol %s: %s: %s; retrying the same %s", serial, what, s.error_message(), what));
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(500 << k));
    }
    s = attempt();
    if (s.error_code() != grpc::StatusCode::UNAVAILABLE && s.error_code() != grpc::StatusCode::DEADLINE_EXCEEDED) {
      break;
    }
  }
  return s;
}

absl::Status RpcFailed(const grpc::Status& s, grpc::Status* rpc_error) {
  *rpc_error = s;
  return absl::UnknownError(s.error_message());
}

}  // namespace

absl::StatusOr<EolStationResult> RunEolStation(v1::CalibrationService::StubInterface& stub,
                                               const io::RecordingSet& set, const EolStationOptions& o,
                                               grpc::Status* rpc_error) {
  *rpc_error = grpc::Status::OK;
  auto log = [&](const std::string& line) {
    if (o.log) o.log(line);
  };
  EolStationResult out;
  const std::string serial = set.manifest.serial;
  out.serial = serial;
  log(absl::StrFormat("eol %s: identifying %zu points", serial, set.waveforms.size()));
  auto ids = IdentifySet(set);
  if (!ids.ok()) return ids.status();
  // Stream the per-point results (one message per point, as a station does
  // while the motor is on the bench).
  v1::IngestHfResultsResponse& ing = out.ingest;
  const StreamTotals points_sent{0, static_cast<int64_t>(ids->points.size()), 0, HfPointsSha256(ids->points)};
  {
    for (const auto& f : ids->failures) log(absl::StrFormat("eol %s: point not identified: %s", serial, f));
    std::vector<v1::IngestHfResultsRequest> msgs;
    std::string content;
    for (const auto& r : ids->points) {
      v1::IngestHfResultsRequest m;
      *m.add_points() = ToProto(r);
      m.AppendToString(&content);
      msgs.push_back(std::move(m));
    }
    if (msgs.empty()) msgs.emplace_back();
    auto& first = msgs.front();
    first.set_serial(serial);
    first.set_station_id(o.station_id);
    // The stream declares its end: the service refuses it whole when a
    // message is lost, cut or fails to parse (docs/service.md).
    first.set_end_follows(true);
    auto* mo = first.mutable_motor();
    mo->set_pole_pairs(set.manifest.motor.pole_pairs);
    mo->set_rs_ohm(set.manifest.motor.rs_ohm.value_or(0));
    mo->set_psi_pm_wb(set.manifest.motor.psi_pm_wb.value_or(0));
    // The run's idempotency key is its content: a retry after a lost reply
    // (UNAVAILABLE, DEADLINE_EXCEEDED) stores nothing twice.
    first.set_idempotency_key("eol-" + io::Sha256Hex(content).substr(0, 40));
    {
      v1::IngestHfResultsRequest last;
      last.mutable_end()->set_messages(static_cast<int64_t>(msgs.size()) + 1);
      last.mutable_end()->set_count(static_cast<int64_t>(ids->points.size()));
      last.mutable_end()->set_sha256(points_sent.sha256);
      msgs.push_back(std::move(last));
    }
    const grpc::Status s = WithRetries(serial, "run", o, [&] {
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(60));
      auto writer = stub.IngestHfResults(&ctx, &ing);
      for (const auto& m : msgs) {
        if (!writer->Write(m)) break;
      }
      writer->WritesDone();
      return writer->Finish();
    });
    if (!s.ok()) return RpcFailed(s, rpc_error);
  }
  // What the service stored must be what this station sent: count and digest.
  if (auto st = CheckStored(points_sent, {0, ing.accepted(), 0, ing.points_sha256()}, "points"); !st.ok()) {
    return absl::Status(st.code(), absl::StrCat(serial, ": run ", ing.run_id(), ": ", st.message()));
  }
  log(absl::StrFormat("eol %s: %d points stored (run %d, sha256 %s, as sent)", serial, ing.accepted(), ing.run_id(),
                      ing.points_sha256().substr(0, 16)));
  // The raw set, so that the service can diagnose this serial (Diagnose
  // reads the latest stored recording) and fit it from everything the set
  // holds, as `fluxcal fit SET` does. Uploaded before the fit: a failed
  // upload leaves no calibration version behind, and rerunning the flow
  // replays both ingests by their keys instead of storing them twice.
  if (!o.upload_recording_dir.empty()) {
    auto files = SetFiles(o.upload_recording_dir, set.manifest);
    if (!files.ok()) return files.status();
    std::string content;
    for (const auto& [name, data] : *files) content += name + '\n' + std::to_string(data.size()) + '\n' + data;
    const std::string key = "eolrec-" + io::Sha256Hex(content).substr(0, 40);
    const StreamTotals files_sent{0, static_cast<int64_t>(files->size()), RecordingFilesBytes(*files),
                                  RecordingFilesSha256(*files)};
    log(absl::StrFormat("eol %s: uploading the recording (%zu files, %zu bytes)", serial, files->size(),
                        content.size()));
    out.recording.emplace();
    v1::IngestRecordingResponse& rec = *out.recording;
    const grpc::Status s = WithRetries(serial, "recording upload", o, [&] {
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(300));
      auto writer = stub.IngestRecording(&ctx, &rec);
      // Chunks well under the service's message limit; the first names the
      // serial, the station and the key.
      constexpr size_t kChunk = 1 << 20;
      bool first = true, open = true;
      int64_t chunks = 0;
      for (auto it = files->begin(); open && it != files->end(); ++it) {
        const auto& [name, data] = *it;
        // An empty file still goes out as one chunk, so the set is complete.
        for (size_t off = 0; open && (off == 0 || off < data.size()); off += kChunk) {
          v1::RecordingChunk c;
          if (first) {
            c.set_serial(serial);
            c.set_station_id(o.station_id);
            c.set_idempotency_key(key);
            c.set_end_follows(true);
            first = false;
          }
          c.set_path(name);
          c.set_data(data.substr(off, kChunk));
          open = writer->Write(c);   // false: the stream broke; Finish says why
          ++chunks;
        }
      }
      if (open) {
        // The declared end: what was sent, checked by the service before
        // anything is stored.
        v1::RecordingChunk last;
        last.mutable_end()->set_messages(chunks + 1);
        last.mutable_end()->set_count(files_sent.count);
        last.mutable_end()->set_bytes(files_sent.bytes);
        last.mutable_end()->set_sha256(files_sent.sha256);
        writer->Write(last);
      }
      writer->WritesDone();
      return writer->Finish();
    });
    if (!s.ok()) return RpcFailed(s, rpc_error);
    if (auto st = CheckStored(files_sent, {0, rec.files(), rec.files_bytes(), rec.files_sha256()}, "files");
        !st.ok()) {
      return absl::Status(st.code(), absl::StrCat(serial, ": recording run ", rec.run_id(), ": ", st.message()));
    }
    log(absl::StrFormat("eol %s: recording %s stored (run %d, %d points%s)", serial,
                        rec.recording_sha256().substr(0, 16), rec.run_id(), rec.points(),
                        rec.replayed() ? ", replayed" : ""));
  }
  log(absl::StrFormat("eol %s: fitting", serial));
  v1::FitRequest fr;
  fr.set_serial(serial);
  fr.set_model(o.model);
  {
    grpc::ClientContext ctx;
    ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
    if (auto s = stub.Fit(&ctx, fr, &out.fit); !s.ok()) return RpcFailed(s, rpc_error);
  }
  if (o.fetch_tables && out.fit.pass()) {
    for (auto [table, format] : {std::pair<const char*, const char*>{"mtpa", "cdfx"}, {"fw", "dcm"}}) {
      v1::ExportTableRequest er;
      er.set_serial(serial);
      er.set_version(out.fit.calibration().version());
      er.set_table(table);
      er.set_format(format);
      // The drive's Udc as the set states it (a run of HF results does not
      // carry it into the store); without one the service asks for it.
      if (set.manifest.drive.udc_v) er.set_udc_v(*set.manifest.drive.udc_v);
      v1::ExportTableResponse resp;
      grpc::ClientContext ctx;
      ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(120));
      if (auto s = stub.ExportTable(&ctx, er, &resp); !s.ok()) return RpcFailed(s, rpc_error);
      if (o.on_table) {
        if (auto st = o.on_table(table, format, resp); !st.ok()) return st;
      }
    }
  }
  return out;
}

}  // namespace fluxcal::pipeline
