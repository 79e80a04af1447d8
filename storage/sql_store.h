// The one implementation of storage::Store, over the seam in
// storage/sql_source.h: every use case (versions, migrations, the hash
// chains, audit inside the write's transaction, idempotency, imports) is
// written here once; a backend only supplies connections and its dialect
// (storage/dialect.h). Reads are in sql_store_read.cc, writes and
// migrations in sql_store.cc.
//
// Concurrency: every write is one transaction begun with the dialect's
// write BEGIN. Calibration versions per serial are gap-free across
// processes: on SQLite the file's write lock is taken before MAX(version)
// is read, on PostgreSQL the motor row is locked FOR UPDATE first.
// Migrations and appends to the release chain take the dialect's advisory
// lock where it has one, so several servers starting at once migrate once.
#ifndef FLUXCAL_STORAGE_SQL_STORE_H_
#define FLUXCAL_STORAGE_SQL_STORE_H_

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "storage/dialect.h"
#include "storage/sql_source.h"
#include "storage/store.h"

namespace fluxcal::storage {

class SqlStore final : public Store {
 public:
  // Applies pending migrations (Store::OpenOptions: `create` false refuses
  // a database without fluxcal's schema_version table, NotFound).
  static absl::StatusOr<std::unique_ptr<SqlStore>> Open(std::unique_ptr<SqlPool> pool, bool create,
                                                        JsonToModelFn json_to_model);

  std::string Backend() const override { return pool_->dialect().name; }
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

  // Online backup into a new file (SQLite; Unimplemented on PostgreSQL).
  absl::Status Backup(const std::string& dest_path) { return pool_->BackupTo(dest_path); }

 private:
  explicit SqlStore(std::unique_ptr<SqlPool> pool) : pool_(std::move(pool)) {}
  const Dialect& dialect() const { return pool_->dialect(); }

  // One write transaction on one connection: commits when fn is OK, rolls
  // back otherwise (also when COMMIT fails).
  absl::Status Write(const std::function<absl::Status(SqlSource&)>& fn);
  // fn on one connection, outside a write transaction; its result.
  template <typename Fn>
  auto Read(Fn fn) -> decltype(fn(std::declval<SqlSource&>()));

  absl::Status Migrate(bool create, const JsonToModelFn& json_to_model);
  // The data steps of migrations v7 (releases stored before it join the
  // chain) and v8 (stored JSON converted, ConvertStoredJson).
  absl::Status LinkStoredReleases(SqlSource& s);
  absl::Status ConvertStoredJsonIn(SqlSource& s, const JsonToModelFn& json_to_model);
  // Appends the link of release `r` to the release chain, inside the
  // caller's transaction (which holds the release-chain lock).
  absl::Status AppendReleaseLink(SqlSource& s, const ReleaseRow& r);
  // Inserts `audit` (if any) inside the caller's transaction.
  absl::Status InsertAudit(SqlSource& s, const AuditContext* audit, int64_t written_id, bool replayed);

  std::unique_ptr<SqlPool> pool_;
};

template <typename Fn>
auto SqlStore::Read(Fn fn) -> decltype(fn(std::declval<SqlSource&>())) {
  using Out = decltype(fn(std::declval<SqlSource&>()));
  std::optional<Out> out;
  auto st = pool_->WithSource([&](SqlSource& s) -> absl::Status {
    out.emplace(fn(s));
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return std::move(*out);
}

// Row readers and column lists shared by the two halves of SqlStore.
namespace sql {
inline constexpr char kCalCols[] =
    "SELECT serial, version, COALESCE(run_id, 0), created_utc, model, psi_pm_wb, rms_relative, verdict, "
    "calibration_json, model_pb FROM calibrations ";
inline constexpr char kChainCols[] = "SELECT serial, version, prev_sha256, row_sha256 FROM calibration_chain ";
CalibrationRow ReadCal(const SqlRow& r);
ChainRow ReadChain(const SqlRow& r);
std::vector<SqlValue> CalibrationValues(const CalibrationRow& c);
inline constexpr char kInsertCalibration[] =
    "INSERT INTO calibrations (serial, version, run_id, created_utc, model, psi_pm_wb, rms_relative, verdict, "
    "calibration_json, model_pb) VALUES (?,?,?,?,?,?,?,?,?,?)";
inline constexpr char kInsertConversion[] =
    "INSERT INTO calibration_conversions (serial, version, json_sha256, row_sha256, converted_utc) "
    "VALUES (?,?,?,?,?)";
inline constexpr char kInsertAudit[] =
    "INSERT INTO audit (utc, identity, role, peer, request_id, rpc, serial, detail) VALUES (?,?,?,?,?,?,?,?)";
inline constexpr char kInsertRecording[] =
    "INSERT INTO recordings (sha256, size_bytes, zlib_data) VALUES (?,?,?) ON CONFLICT (sha256) DO NOTHING";
// The run's points, in order, for SqlSource::InsertRows.
absl::Status InsertPoints(SqlSource& s, int64_t run_id, const std::vector<HfPointRow>& points);
}  // namespace sql

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_SQL_STORE_H_
