// Runs into the store: identified HF points, or a raw recording
// (identified here, stored with its points) for a serial.
#include "pipeline/pipeline.h"

#include <filesystem>
#include <optional>
#include <set>

#include "absl/strings/str_cat.h"
#include "pipeline/internal.h"
#include "pipeline/ingest_stream.h"
#include "pipeline/recording_archive.h"
#include "io/sha256.h"

namespace fluxcal::pipeline {

namespace internal {

absl::StatusOr<std::string> RecordingShaOfRun(storage::Store& store, const std::string& serial, int64_t run_id) {
  auto history = store.History(serial);
  if (!history.ok()) return history.status();
  for (const auto& h : *history) {
    if (h.run_id == run_id && h.kind == "recording" && !h.detail.empty()) return h.detail;
  }
  return absl::NotFoundError(absl::StrCat("run ", run_id, " of '", serial, "' has no raw recording"));
}

}  // namespace internal

using internal::RecordingShaOfRun;

absl::StatusOr<int64_t> IngestHfRun(storage::Store& store, const std::string& serial, const std::string& station,
                                    const std::optional<MotorNominal>& motor,
                                    const std::vector<IdentifiedPoint>& points, int rejected,
                                    const std::string& idempotency_key, bool* replayed,
                                    const storage::AuditContext* audit) {
  storage::MotorRow m{serial, 0, 0.0, 0.0, ""};
  if (motor) {
    if (motor->pole_pairs < 1 || motor->pole_pairs > 100) {
      return absl::InvalidArgumentError(absl::StrCat("motor.pole_pairs: expected 1..100, got ", motor->pole_pairs));
    }
    m.pole_pairs = motor->pole_pairs; m.rs_ohm = motor->rs_ohm; m.psi_pm_wb = motor->psi_pm_wb;
  } else if (auto known = store.GetMotor(serial); known.ok()) {
    m = *known;
  } else if (known.status().code() == absl::StatusCode::kNotFound) {
    return absl::InvalidArgumentError(
        absl::StrCat("motor: required for serial '", serial, "' (not known to the store yet)"));
  } else {
    return known.status();
  }
  if (points.empty()) {
    return absl::InvalidArgumentError(rejected > 0 ? absl::StrCat("points: no valid point in the stream (", rejected,
                                                                  " rejected)")
                                                   : std::string("points: the stream carried no point"));
  }
  return store.IngestHfRun(m, station, "hf_run", points, "", {}, 0, idempotency_key, replayed, audit);
}

absl::StatusOr<IngestRecordingResult> IngestRecording(storage::Store& store, const std::string& serial,
                                                      const std::string& station, const io::RecordingFiles& files,
                                                      const std::string& idempotency_key,
                                                      const storage::AuditContext* audit,
                                                      const CancelledFn& cancelled, std::string* sha256_before_store) {
  auto set = io::ReadRecordingSetFromFiles(files, "");
  if (!set.ok()) return absl::InvalidArgumentError(std::string(set.status().message()));
  // Files the manifest does not name are junk: refuse rather than store them.
  {
    auto norm = [](const std::string& f) { return std::filesystem::path(f).lexically_normal().generic_string(); };
    std::set<std::string> named = {"manifest.json"};
    for (const auto& p : set->manifest.points) named.insert(norm(p.file));
    if (set->manifest.steady_state) named.insert(norm(*set->manifest.steady_state));
    if (set->manifest.hf_results) named.insert(norm(*set->manifest.hf_results));
    for (const auto& [name, data] : files) {
      if (!named.count(name)) {
        return absl::InvalidArgumentError(absl::StrCat("path: file '", name, "' is not referenced by manifest.json"));
      }
    }
  }
  if (set->manifest.serial != serial) {
    return absl::InvalidArgumentError(
        absl::StrCat("serial: stream serial '", serial, "' differs from the manifest's '", set->manifest.serial, "'"));
  }
  ident::IdentifyOptions idopt;
  idopt.cancelled = cancelled;
  auto ids = pipeline::IdentifySet(*set, idopt);
  if (ids.status().code() == absl::StatusCode::kCancelled) return ids.status();
  if (!ids.ok()) return absl::InvalidArgumentError(std::string(ids.status().message()));
  const std::string archive = EncodeRecordingArchive(files);
  auto z = Deflate(archive);
  if (!z.ok()) return z.status();
  IngestRecordingResult out;
  out.sha256 = io::Sha256Hex(archive);
  if (sha256_before_store != nullptr) *sha256_before_store = out.sha256;
  if (cancelled && cancelled()) return absl::CancelledError("ingest: cancelled by the caller before storing");
  const auto& mm = set->manifest.motor;
  storage::MotorRow motor{serial, mm.pole_pairs, mm.rs_ohm.value_or(0.0), mm.psi_pm_wb.value_or(0.0), ""};
  auto run = store.IngestHfRun(motor, station, "recording", ids->points, out.sha256, *z,
                               static_cast<int64_t>(archive.size()), idempotency_key, &out.replayed, audit);
  if (!run.ok()) return run.status();
  out.run_id = *run;
  out.recording_bytes = static_cast<int64_t>(archive.size());
  out.stored_bytes = static_cast<int64_t>(z->size());
  const io::RecordingFiles* accepted = &files;
  io::RecordingFiles stored_files;
  if (out.replayed) {
    // The run stored before under this key, read back: a retry whose
    // content differs from the first try must not pass the client's check.
    auto stored_sha = RecordingShaOfRun(store, serial, *run);
    if (!stored_sha.ok()) return stored_sha.status();
    auto row = store.GetRecordingRow(*stored_sha);
    if (!row.ok()) return row.status();
    auto stored_archive = Inflate(row->zlib_data, kMaxStoredRecordingBytes);
    if (!stored_archive.ok()) return stored_archive.status();
    auto decoded = DecodeRecordingArchive(*stored_archive);
    if (!decoded.ok()) return decoded.status();
    stored_files = std::move(*decoded);
    accepted = &stored_files;
    out.sha256 = *stored_sha;
    out.recording_bytes = static_cast<int64_t>(stored_archive->size());
    out.stored_bytes = static_cast<int64_t>(row->zlib_data.size());
  }
  auto digest = DigestOfIngest(store, *run, out.replayed, ids->points);
  if (!digest.ok()) return digest.status();
  out.points = static_cast<int>(digest->points);
  out.points_sha256 = digest->points_sha256;
  out.files = static_cast<int>(accepted->size());
  out.files_bytes = RecordingFilesBytes(*accepted);
  out.files_sha256 = RecordingFilesSha256(*accepted);
  return out;
}

}  // namespace fluxcal::pipeline
