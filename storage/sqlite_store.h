// SQLite backend of storage::Store: one file (or ":memory:"), WAL journal,
// synchronous=FULL, one connection guarded by a mutex (SQLite has one
// writer anyway; reads are short). Several processes may open the same file;
// BEGIN IMMEDIATE takes the file's write lock before the version number is
// read, so versions stay gap-free across processes too.
#ifndef FLUXCAL_STORAGE_SQLITE_STORE_H_
#define FLUXCAL_STORAGE_SQLITE_STORE_H_

#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "storage/sqlite.h"
#include "storage/store.h"

namespace fluxcal::storage {

class SqliteStore final : public Store {
 public:
  // `create` false: see Store::OpenOptions.
  // `json_to_model`: the v8 migration's converter (Store::OpenOptions).
  static absl::StatusOr<std::unique_ptr<SqliteStore>> Open(const std::string& path, bool create = true,
                                                           JsonToModelFn json_to_model = {});

  std::string Backend() const override { return "sqlite"; }
  absl::StatusOr<int> SchemaVersion() override;
  absl::StatusOr<int64_t> IngestHfRun(const MotorRow& motor, const std::string& station, const std::string& kind,
                                      const std::vector<HfPointRow>& points, const std::string& recording_sha256,
                                      const std::vector<uint8_t>& recording_compressed,
                                      int64_t recording_bytes, const std::string& idempotency_key = "",
                                      bool* replayed = nullptr, const AuditContext* audit = nullptr) override;
  absl::StatusOr<MotorRow> GetMotor(const std::string& serial) override;
  absl::Status Release(const std::string& serial, int version, const std::string& released_by,
                       const AuditContext* audit = nullptr) override;
  absl::StatusOr<int> LatestReleasedVersion(const std::string& serial) override;
  absl::StatusOr<bool> IsReleased(const std::string& serial, int version) override;
  absl::StatusOr<ReleaseRow> GetRelease(const std::string& serial, int version) override;
  absl::StatusOr<std::vector<ReleaseLinkRow>> AllReleaseLinks() override;
  absl::StatusOr<ReleaseLinkRow> ReleaseLink(const std::string& serial, int version) override;
  absl::StatusOr<ReleaseLinkRow> ReleaseLinkAt(int64_t seq) override;
  absl::Status AppendAudit(const AuditRow& row) override;
  absl::StatusOr<std::vector<AuditRow>> AuditOf(const std::string& serial) override;
  absl::StatusOr<std::vector<ChainRow>> AllChainRows() override;
  absl::StatusOr<ChainRow> ChainLink(const std::string& serial, int version) override;
  absl::StatusOr<std::vector<ConversionRow>> AllConversions() override;
  absl::StatusOr<std::optional<ConversionRow>> Conversion(const std::string& serial, int version) override;
  absl::Status ImportConversions(const std::vector<ConversionRow>& conversions) override;
  absl::StatusOr<std::vector<HfPointRow>> LatestRunPoints(const std::string& serial, int64_t* run_id) override;
  absl::StatusOr<int> AddCalibration(const CalibrationRow& row, const AuditContext* audit = nullptr) override;
  absl::StatusOr<CalibrationRow> GetCalibration(const std::string& serial, int version) override;
  absl::StatusOr<std::vector<CalibrationRow>> LatestCalibrations() override;
  absl::StatusOr<std::vector<MotorSummaryRow>> ListMotors(const std::string& prefix, bool only_failed, int offset,
                                                          int limit) override;
  absl::StatusOr<std::vector<HistoryRow>> History(const std::string& serial) override;
  absl::StatusOr<std::vector<uint8_t>> GetRecording(const std::string& sha256) override;
  absl::StatusOr<std::string> LatestRecordingSha(const std::string& serial) override;

  absl::StatusOr<std::vector<MotorRow>> AllMotors() override;
  absl::StatusOr<std::vector<RunRow>> AllRuns() override;
  absl::StatusOr<std::vector<HfPointRow>> RunPoints(int64_t run_id) override;
  absl::StatusOr<RecordingRow> GetRecordingRow(const std::string& sha256) override;
  absl::StatusOr<std::vector<CalibrationRow>> AllCalibrations() override;
  absl::StatusOr<std::vector<ReleaseRow>> AllReleases() override;
  absl::StatusOr<std::vector<AuditRow>> AllAudit() override;
  absl::Status ImportMotor(const MotorRow& motor) override;
  absl::Status ImportRun(const RunRow& run, const std::vector<HfPointRow>& points,
                         const RecordingRow* recording) override;
  absl::Status ImportCalibration(const CalibrationRow& row) override;
  absl::Status ImportTrail(const std::vector<ReleaseRow>& releases, const std::vector<AuditRow>& audit,
                           const std::vector<ChainRow>& chain,
                           const std::vector<ReleaseLinkRow>& release_chain) override;

  // Online backup (sqlite3_backup_*) into a new file at `dest_path`: a
  // consistent copy while the store keeps serving.
  absl::Status Backup(const std::string& dest_path);

 private:
  SqliteStore(std::string path, std::unique_ptr<Database> writer) : path_(std::move(path)), writer_(std::move(writer)) {}
  absl::Status Migrate(const JsonToModelFn& json_to_model);
  // The v8 migration's data step: every version stored as JSON converted
  // where ConvertStoredJson allows, with its record and one audit row.
  absl::Status ConvertStoredJsonLocked(const JsonToModelFn& json_to_model);
  absl::StatusOr<CalibrationRow> CalibrationLocked(const std::string& serial, int version);
  absl::StatusOr<std::vector<ConversionRow>> ConversionsLocked(const std::string& where,
                                                               const std::vector<SqlValue>& args);
  // Appends the link of release `r` to the release chain, inside the
  // caller's transaction (Release, and the v7 migration for releases
  // stored before it).
  absl::Status AppendReleaseLinkLocked(const ReleaseRow& r);
  absl::StatusOr<std::vector<ReleaseLinkRow>> ReleaseLinksLocked(const std::string& where,
                                                                 const std::vector<SqlValue>& args);
  absl::StatusOr<std::vector<HfPointRow>> PointsLocked(int64_t run_id);
  absl::Status InsertPointsLocked(int64_t run_id, const std::vector<HfPointRow>& points);
  // Inserts `audit` (if any) inside the caller's transaction.
  absl::Status InsertAuditLocked(const AuditContext* audit, int64_t written_id, bool replayed);

  std::string path_;
  std::mutex write_mu_;
  std::unique_ptr<Database> writer_;
};

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_SQLITE_STORE_H_
