// Diagnosis over the store: a stored recording read back, a stored run
// diagnosed, and a diagnosed calibration stored as a new version.
#include "pipeline/pipeline.h"

#include <optional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "pipeline/calibration_codec.h"
#include "pipeline/internal.h"
#include "pipeline/recording_archive.h"

namespace fluxcal::pipeline {

absl::StatusOr<io::RecordingSet> LoadStoredRecording(storage::Store& store, const std::string& sha256) {
  auto blob = store.GetRecording(sha256);
  if (!blob.ok()) return blob.status();
  // Unpacked in memory only (names re-checked), never onto the filesystem.
  auto archive = Inflate(*blob, kMaxStoredRecordingBytes);
  if (!archive.ok()) return archive.status();
  auto files = DecodeRecordingArchive(*archive);
  if (!files.ok()) return files.status();
  return io::ReadRecordingSetFromFiles(*files, "");
}

absl::StatusOr<storage::CalibrationRow> StoreDiagnosedCalibration(storage::Store& store, const std::string& serial,
                                                                  const diag::DiagnosisReport& report,
                                                                  const FitTolerances& tol,
                                                                  const storage::AuditContext* audit) {
  auto motor = store.GetMotor(serial);
  if (!motor.ok()) return motor.status();
  int64_t run_id = 0;
  auto pts = store.LatestRunPoints(serial, &run_id);
  if (!pts.ok()) return pts.status();
  auto cal = diag::DiagnosedCalibration(report);
  if (!cal.ok()) return cal.status();
  storage::CalibrationRow row =
      internal::NewCalibrationRow(serial, *motor, run_id, *cal, report.corrected_data.inductances.size(), 0, tol);
  // The diagnosis block travels in the binary model's extra_json.
  auto model = CalibrationJsonToModel(diag::MarkedCalibrationJson(report, *cal).dump());
  if (!model.ok()) return model.status();
  row.model_pb = std::move(*model);
  storage::AuditContext a;
  if (audit != nullptr) {
    a = *audit;
    std::vector<std::string> effects;
    for (const auto& f : report.findings) effects.push_back(f.effect);
    a.detail = [model = row.model, verdict = row.verdict, found = absl::StrJoin(effects, ", ")](int64_t version, bool) {
      return absl::StrCat("version ", version, " (", model, ", diagnosed: ", found.empty() ? "no findings" : found,
                          "): ", verdict);
    };
  }
  auto version = store.AddCalibration(row, audit != nullptr ? &a : nullptr);
  if (!version.ok()) return version.status();
  return StoredRowView(store, serial, *version);
}

absl::StatusOr<diag::DiagnosisReport> DiagnoseStored(storage::Store& store, const std::string& serial,
                                                     const CancelledFn& cancelled) {
  auto sha = store.LatestRecordingSha(serial);
  if (!sha.ok()) return sha.status();
  auto set = LoadStoredRecording(store, *sha);
  if (!set.ok()) return set.status();
  diag::DiagnoseOptions o;
  o.cancelled = cancelled;
  return diag::Diagnose(*set, o);
}

}  // namespace fluxcal::pipeline
