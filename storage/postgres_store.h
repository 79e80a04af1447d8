// PostgreSQL backend of storage::Store, on libpq (Debian libpq-dev; the C
// API is small enough here that a C++ wrapper would not pay).
//
// Stateless servers share one database: nothing is cached between calls.
// A small pool of connections serves concurrent calls (a libpq connection
// is not thread-safe). Every write is one transaction, committed with the
// server's default synchronous_commit=on, so an acknowledgement means the
// commit is on disk. Migrations run under a transaction-scoped advisory lock
// so several servers starting at once migrate once. Calibration versions:
// AddCalibration locks the motor row (SELECT ... FOR UPDATE) before reading
// MAX(version), so concurrent fits of one serial from any number of
// processes get n+1, n+2, ... with no duplicate and no gap.
#ifndef FLUXCAL_STORAGE_POSTGRES_STORE_H_
#define FLUXCAL_STORAGE_POSTGRES_STORE_H_

#include <condition_variable>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "storage/store.h"

typedef struct pg_conn PGconn;

namespace fluxcal::storage {

class PostgresStore final : public Store {
 public:
  // `url`: a libpq connection URI ("postgresql://user@host:port/db").
  // `create` false: the database must hold a fluxcal store already
  // (Store::OpenOptions).
  static absl::StatusOr<std::unique_ptr<PostgresStore>> Open(const std::string& url, int max_connections = 16,
                                                             bool create = true, JsonToModelFn json_to_model = {});
  ~PostgresStore() override;

  std::string Backend() const override { return "postgresql"; }
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

 private:
  PostgresStore(std::string url, int max_connections) : url_(std::move(url)), max_(max_connections) {}
  absl::StatusOr<PGconn*> Acquire();
  void Release(PGconn* c);
  // Runs fn on a pooled connection; a connection found broken is dropped.
  absl::Status WithConn(const std::function<absl::Status(PGconn*)>& fn);
  // BEGIN ... COMMIT around fn; ROLLBACK when fn fails.
  absl::Status WithTransaction(const std::function<absl::Status(PGconn*)>& fn);
  absl::Status Migrate(bool create, const JsonToModelFn& json_to_model);
  absl::StatusOr<std::vector<ReleaseLinkRow>> ReleaseLinks(const std::string& where, const std::vector<std::string>& args);

  std::string url_;
  int max_;
  std::mutex mu_;
  std::condition_variable cv_;
  std::vector<PGconn*> idle_;
  int open_ = 0;
};

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_POSTGRES_STORE_H_
