// The SQLite store of fluxcal: motors per serial, ingest runs with their HF
// points, raw recordings (zlib-compressed, keyed by SHA-256 content hash)
// and immutable calibration versions. Schema in docs/service.md.
//
// Concurrency: one connection guarded by a mutex (SQLite has one writer
// anyway; reads are short). Every write is one transaction, durable on
// return (WAL, synchronous=FULL). Several processes may open the same file.
//
// Errors: InvalidArgument (bad input), NotFound (unknown serial/version),
// AlreadyExists (constraint), Internal/Unavailable (SQLite).
#ifndef FLUXCAL_STORAGE_STORE_H_
#define FLUXCAL_STORAGE_STORE_H_

#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "storage/sqlite.h"

namespace fluxcal::storage {

inline constexpr int kSchemaVersion = 2;

struct MotorRow {
  std::string serial;
  int pole_pairs = 4;
  double rs_ohm = 0, psi_pm_wb = 0;
};

struct HfPointRow {
  std::string point_id;
  double id_a = 0, iq_a = 0, speed_rpm = 0, ld_h = 0, lq_h = 0;
  std::optional<double> ldq_h;
  double ld_h_std = 0, lq_h_std = 0, ldq_h_std = 0, temperature_c = 25;
  bool reliable = true;
};

struct CalibrationRow {
  std::string serial;
  int version = 0;
  int64_t run_id = 0;
  std::string created_utc, model, verdict, calibration_json;
  double psi_pm_wb = 0, rms_relative = 0;
};

struct MotorSummaryRow {
  std::string serial, verdict, updated_utc;
  int latest_version = 0, runs = 0;
};

struct HistoryRow {
  std::string created_utc, kind, detail;
  int64_t run_id = 0;
  int version = 0;
};

class Store {
 public:
  // Opens or creates the database and applies pending migrations in order.
  static absl::StatusOr<std::unique_ptr<Store>> Open(const std::string& path);

  absl::StatusOr<int> SchemaVersion();

  // One transaction: upserts the motor, creates a run, inserts all points.
  absl::StatusOr<int64_t> IngestHfRun(const MotorRow& motor, const std::string& station,
                                      const std::string& kind, const std::vector<HfPointRow>& points,
                                      const std::string& recording_sha256 = "",
                                      const std::vector<uint8_t>& recording_compressed = {},
                                      int64_t recording_bytes = 0);

  absl::StatusOr<MotorRow> GetMotor(const std::string& serial);
  // Points of the serial's latest run (and its id).
  absl::StatusOr<std::vector<HfPointRow>> LatestRunPoints(const std::string& serial, int64_t* run_id);

  // Appends version n+1 for the serial (immutable; never overwrites).
  absl::StatusOr<int> AddCalibration(const CalibrationRow& row);
  absl::StatusOr<CalibrationRow> GetCalibration(const std::string& serial, int version /*0 latest*/);
  absl::StatusOr<std::vector<CalibrationRow>> LatestCalibrations();

  absl::StatusOr<std::vector<MotorSummaryRow>> ListMotors(const std::string& prefix, bool only_failed,
                                                          int offset, int limit);
  absl::StatusOr<std::vector<HistoryRow>> History(const std::string& serial);
  absl::StatusOr<std::vector<uint8_t>> GetRecording(const std::string& sha256);
  // SHA-256 of the serial's latest stored raw recording.
  absl::StatusOr<std::string> LatestRecordingSha(const std::string& serial);

 private:
  explicit Store(std::string path, std::unique_ptr<Database> writer)
      : path_(std::move(path)), writer_(std::move(writer)) {}
  absl::Status Migrate();

  std::string path_;
  std::mutex write_mu_;
  std::unique_ptr<Database> writer_;
};

std::string NowUtc();

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_STORE_H_
