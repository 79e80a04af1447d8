// The store of fluxcal: motors per serial, ingest runs with their HF points,
// raw recordings (zlib-compressed, keyed by SHA-256 content hash) and
// immutable calibration versions. Schema in docs/service.md.
//
// `Store` is the storage interface; it only stores (no fitting, no tables:
// the use cases live in pipeline/). One implementation, SqlStore
// (storage/sql_store.h), holds every use case once over a narrow seam
// (storage/sql_source.h: connect, execute with bound parameters,
// begin/commit/rollback) with two backends:
//   - SQLite (storage/sqlite_source.h): the embedded default, one file;
//   - PostgreSQL (storage/postgres_source.h, libpq; compiled only when
//     configure finds libpq): several stateless servers on one database.
// What differs between the two is data (storage/dialect.h): the ordered
// migrations (version table `schema_version`) and a few clauses. Both
// refuse UPDATE/DELETE of calibration versions with triggers, and make
// every write one transaction that is durable when the call returns.
// Calibration versions (per serial) and releases (one chain for the store)
// are hash-chained; VerifyChains recomputes both, and compares with a chain
// head kept outside the database (an anchor) to find removed newest rows.
// Calibration versions per serial are unique and gap-free also under
// concurrent AddCalibration calls from different processes.
//
// Errors: InvalidArgument (bad input), NotFound (unknown serial/version),
// AlreadyExists (constraint), Internal/Unavailable (database).
#ifndef FLUXCAL_STORAGE_STORE_H_
#define FLUXCAL_STORAGE_STORE_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace fluxcal::storage {

inline constexpr int kSchemaVersion = 9;

struct MotorRow {
  std::string serial;
  int pole_pairs = 0;                 // always stated by the station (1..100)
  double rs_ohm = 0, psi_pm_wb = 0;   // 0: not stated
  std::string created_utc;   // set by the store
};

// One identified HF point as stored (the project's identified-point type,
// pipeline::IdentifiedPoint; its converters from/to identification, fitting
// and protobuf live in pipeline/points.h, nowhere else).
struct HfPointRow {
  std::string point_id;
  double id_a = 0, iq_a = 0, speed_rpm = 0, ld_h = 0, lq_h = 0;
  std::optional<double> ldq_h;
  double ld_h_std = 0, lq_h_std = 0, ldq_h_std = 0, temperature_c = 25;
  bool reliable = true;
  // The radius of the flux circle the point's rotating injection drove,
  // Wb (fit::InductanceObservation::hf_flux_radius_wb): what the fit needs
  // to predict the point as the injection measured it. Unset where the
  // station did not say (schema v9; points stored before have none).
  std::optional<double> hf_flux_radius_wb;
};

struct RunRow {
  int64_t run_id = 0;
  std::string serial, station, kind, recording_sha256 /* "" = none */, created_utc;
  std::string idempotency_key;   // "" = none
};

struct RecordingRow {
  std::string sha256;
  int64_t size_bytes = 0;               // uncompressed
  std::vector<uint8_t> zlib_data;
};

// One calibration version. Its content is one of (the store does not read
// either; pipeline/calibration_codec.h does):
//  - model_pb: the binary fitted model (fluxcal.v1.CalibrationModel), what
//    every version is stored as since schema v8 (calibration_json "");
//  - calibration_json: the decimal JSON every version was stored as before
//    v8, kept only for a version the v8 migration did not convert (no chain
//    link, a link that did not verify, or JSON the codec could not read).
struct CalibrationRow {
  std::string serial;
  int version = 0;
  int64_t run_id = 0;
  std::string created_utc, model, verdict, calibration_json;
  double psi_pm_wb = 0, rms_relative = 0;
  std::string model_pb;   // bytes; "" for a version stored as JSON
};

// The record of one version the v8 migration converted from JSON to binary
// (ConvertStoredJson). Its chain link hashed the JSON text, which is gone;
// the record says what that text was (json_sha256) and links the converted
// row to the link: row_sha256 = ConversionRowSha256 (below), so VerifyChains
// recomputes it as it recomputes a link.
struct ConversionRow {
  std::string serial;
  int version = 0;
  std::string json_sha256, row_sha256, converted_utc;
};

// The codec the v8 migration converts stored JSON with (the store knows no
// calibration format: pipeline::OpenStore passes pipeline/calibration_codec.h's
// CalibrationJsonToModel). An error leaves that version as JSON.
using JsonToModelFn = std::function<absl::StatusOr<std::string>(const std::string& calibration_json)>;

struct MotorSummaryRow {
  std::string serial, verdict, updated_utc;
  int latest_version = 0, runs = 0;
};

// One write to the store, as the service saw it (append-only).
struct AuditRow {
  int64_t id = 0;
  std::string utc, identity, role, peer, request_id, rpc, serial, detail;
};

// The audit row of one write, inserted by the store inside the write's own
// transaction: the write and its row commit together or not at all (a
// failing audit insert rolls the write back).
struct AuditContext {
  AuditRow row;   // identity, role, peer, request_id, rpc, serial; utc is set by the store
  // The detail from what was written, called inside the transaction: the
  // run id (replayed: the run the idempotency key found) or the calibration
  // version. Unset: row.detail as given.
  std::function<std::string(int64_t written_id, bool replayed)> detail;
};

struct ReleaseRow {
  std::string serial;
  int version = 0;
  std::string released_by, released_utc;
};

// One link of the per-serial hash chain over calibration versions.
struct ChainRow {
  std::string serial;
  int version = 0;
  std::string prev_sha256, row_sha256;
};

// One link of the chain over releases (schema v7): one chain for the whole
// store, in release order (seq 1, 2, ...). `calibration_sha256` is the
// released version's hash (VersionSha256) when it was released.
struct ReleaseLinkRow {
  int64_t seq = 0;
  std::string serial;
  int version = 0;
  std::string calibration_sha256, prev_sha256, row_sha256;
};

struct HistoryRow {
  std::string created_utc, kind, detail;
  int64_t run_id = 0;
  int version = 0;
};

class Store {
 public:
  virtual ~Store() = default;

  struct OpenOptions {
    // false: the store must exist already (commands that only read): a
    // SQLite path that does not exist, or a file or database without
    // fluxcal's schema_version table, is NotFound naming it, and nothing
    // is created. An existing store is still migrated to kSchemaVersion.
    bool create = true;
    // The v8 migration's converter; unset: versions stored as JSON stay JSON
    // (readable as before; only stores opened through the storage library
    // alone, i.e. its tests, do that).
    JsonToModelFn json_to_model;
  };
  // Opens (creating, unless options.create is false) a store and applies
  // pending migrations in order:
  //   "postgresql://..." or "postgres://..."  -> PostgreSQL (libpq URI;
  //       Unimplemented, saying so, in a build without PostgreSQL);
  //   "sqlite:PATH", a file path or ":memory:" -> SQLite.
  static absl::StatusOr<std::unique_ptr<Store>> Open(const std::string& url, const OpenOptions& options);
  static absl::StatusOr<std::unique_ptr<Store>> Open(const std::string& url) { return Open(url, OpenOptions{}); }

  virtual std::string Backend() const = 0;   // "sqlite" | "postgresql"
  virtual absl::StatusOr<int> SchemaVersion() = 0;

  // One transaction: upserts the motor, stores the recording (if any, by
  // content hash), creates a run, inserts all points. With a non-empty
  // idempotency key a run already stored for (serial, key) is returned as
  // is (*replayed = true) and nothing but the audit row is written: a
  // client's retry after a lost reply creates no duplicate. With `audit`
  // its row is inserted in the same transaction.
  virtual absl::StatusOr<int64_t> IngestHfRun(const MotorRow& motor, const std::string& station,
                                              const std::string& kind, const std::vector<HfPointRow>& points,
                                              const std::string& recording_sha256 = "",
                                              const std::vector<uint8_t>& recording_compressed = {},
                                              int64_t recording_bytes = 0, const std::string& idempotency_key = "",
                                              bool* replayed = nullptr,
                                              const AuditContext* audit = nullptr) = 0;

  virtual absl::StatusOr<MotorRow> GetMotor(const std::string& serial) = 0;
  // Points of the serial's latest run (and its id).
  virtual absl::StatusOr<std::vector<HfPointRow>> LatestRunPoints(const std::string& serial, int64_t* run_id) = 0;

  // Appends version n+1 for the serial (immutable; never overwrites), its
  // chain link and, with `audit`, its audit row: one transaction.
  virtual absl::StatusOr<int> AddCalibration(const CalibrationRow& row, const AuditContext* audit = nullptr) = 0;
  virtual absl::StatusOr<CalibrationRow> GetCalibration(const std::string& serial, int version /*0 latest*/) = 0;
  virtual absl::StatusOr<std::vector<CalibrationRow>> LatestCalibrations() = 0;

  // Releases (immutable rows): a calibration version approved for
  // flashing. Release: NotFound (no such version), FailedPrecondition (its
  // verdict is not "pass"), AlreadyExists (released before). The verdict is
  // checked inside the same transaction as the insert, and so are the
  // release's chain link (ReleaseRowSha256, appended to the store's one
  // release chain; concurrent releases from several servers are serialised)
  // and the audit row when `audit` is given.
  virtual absl::Status Release(const std::string& serial, int version, const std::string& released_by,
                               const AuditContext* audit = nullptr) = 0;
  // The newest released version, 0 when none.
  virtual absl::StatusOr<int> LatestReleasedVersion(const std::string& serial) = 0;
  virtual absl::StatusOr<bool> IsReleased(const std::string& serial, int version) = 0;
  // The release row of a version; NotFound when it is not released.
  virtual absl::StatusOr<ReleaseRow> GetRelease(const std::string& serial, int version) = 0;
  // Release chain links: all by seq; the link of one released version; the
  // link at `seq` (0: the newest). NotFound when there is none.
  virtual absl::StatusOr<std::vector<ReleaseLinkRow>> AllReleaseLinks() = 0;
  virtual absl::StatusOr<ReleaseLinkRow> ReleaseLink(const std::string& serial, int version) = 0;
  virtual absl::StatusOr<ReleaseLinkRow> ReleaseLinkAt(int64_t seq) = 0;

  // Audit trail (append-only): Append sets utc and writes a row on its own
  // (a write passes its row as AuditContext instead, into its transaction);
  // AuditOf lists a serial's rows oldest first.
  virtual absl::Status AppendAudit(const AuditRow& row) = 0;
  virtual absl::StatusOr<std::vector<AuditRow>> AuditOf(const std::string& serial) = 0;
  // Every chain link, by serial and version.
  virtual absl::StatusOr<std::vector<ChainRow>> AllChainRows() = 0;
  // The chain link of one calibration version (0: the latest chained one);
  // NotFound when it has none. A cheap stand-in for the row's content.
  virtual absl::StatusOr<ChainRow> ChainLink(const std::string& serial, int version) = 0;
  // The v8 conversion records: all, by serial and version; one version's
  // (nullopt when it was not converted).
  virtual absl::StatusOr<std::vector<ConversionRow>> AllConversions() = 0;
  virtual absl::StatusOr<std::optional<ConversionRow>> Conversion(const std::string& serial, int version) = 0;

  virtual absl::StatusOr<std::vector<MotorSummaryRow>> ListMotors(const std::string& prefix, bool only_failed,
                                                                  int offset, int limit) = 0;
  virtual absl::StatusOr<std::vector<HistoryRow>> History(const std::string& serial) = 0;
  virtual absl::StatusOr<std::vector<uint8_t>> GetRecording(const std::string& sha256) = 0;
  // SHA-256 of the serial's latest stored raw recording.
  virtual absl::StatusOr<std::string> LatestRecordingSha(const std::string& serial) = 0;

  // --- Whole-store access, for `fluxcal admin migrate` and content hashes.
  virtual absl::StatusOr<std::vector<MotorRow>> AllMotors() = 0;            // by serial
  virtual absl::StatusOr<std::vector<RunRow>> AllRuns() = 0;                // by run_id
  virtual absl::StatusOr<std::vector<HfPointRow>> RunPoints(int64_t run_id) = 0;
  virtual absl::StatusOr<RecordingRow> GetRecordingRow(const std::string& sha256) = 0;
  virtual absl::StatusOr<std::vector<CalibrationRow>> AllCalibrations() = 0;  // by serial, version
  virtual absl::StatusOr<std::vector<ReleaseRow>> AllReleases() = 0;         // by serial, version
  virtual absl::StatusOr<std::vector<AuditRow>> AllAudit() = 0;              // by id
  // Copies keeping ids, versions and timestamps (into an empty store). Each
  // call is one transaction.
  virtual absl::Status ImportMotor(const MotorRow& motor) = 0;
  virtual absl::Status ImportRun(const RunRow& run, const std::vector<HfPointRow>& points,
                                 const RecordingRow* recording) = 0;
  virtual absl::Status ImportCalibration(const CalibrationRow& row) = 0;
  // Releases, audit rows (ids and times kept) and the links of both chains
  // (hashes kept, so verify-db checks the copy as it checked the source):
  // one transaction, after the calibrations they name.
  virtual absl::Status ImportTrail(const std::vector<ReleaseRow>& releases, const std::vector<AuditRow>& audit,
                                   const std::vector<ChainRow>& chain,
                                   const std::vector<ReleaseLinkRow>& release_chain) = 0;
  // Conversion records as they are (one transaction, after the calibrations).
  virtual absl::Status ImportConversions(const std::vector<ConversionRow>& conversions) = 0;
};

std::string NowUtc();

// The chain hash of a calibration row: SHA-256 (OpenSSL) over `prev_sha256`
// and every stored field, each length-prefixed, doubles as %.17g, and, for
// a row stored as binary (model_pb not empty; schema v8), model_pb as one
// more field after calibration_json (""): a row stored as JSON hashes as it
// always did. Version 1 (or the first version written with schema v6) has
// prev_sha256 "".
std::string CalibrationRowSha256(const std::string& prev_sha256, const CalibrationRow& row);

// The hash of a conversion record: CalibrationRowSha256(SHA-256 over the
// link's row_sha256, json_sha256 and converted_utc, each length-prefixed;
// the converted row). An edit of the row or of the record shows.
std::string ConversionRowSha256(const std::string& link_row_sha256, const ConversionRow& record,
                                const CalibrationRow& converted);

// The v8 migration of one version stored as JSON, written once for both
// backends: converted (the row with model_pb and calibration_json "", and
// its ConversionRow) only when its chain link verifies against the JSON as
// stored and `to_model` reads it; nullopt otherwise: the row stays JSON and
// verify-db judges it exactly as before (an unverifiable row keeps its
// evidence; a version from before the chain keeps the hash its release
// names).
struct ConvertedVersion {
  CalibrationRow row;
  ConversionRow record;
};
std::optional<ConvertedVersion> ConvertStoredJson(const CalibrationRow& row, const ChainRow* link,
                                                  const JsonToModelFn& to_model, const std::string& now_utc);
// The audit detail of the v8 migration: how many of how many versions it
// converted, and the SHA-256 of `records` ("serial\tversion\tjson_sha256\t
// row_sha256\n" per conversion, in (serial, version) order).
std::string ConversionAuditDetail(int converted, int versions, const std::string& records);
// The hash that stands for one stored calibration version (a release and
// an anchor name it): its chain link's row_sha256, or, for a version
// stored before the chain (schema < 6, no link), CalibrationRowSha256("",
// row).
std::string VersionSha256(const CalibrationRow& row, const ChainRow* link);
// The chain hash of a release: SHA-256 over `prev_sha256` (the previous
// link's row_sha256, "" for seq 1), seq, serial, version, released_by,
// released_utc and the released version's VersionSha256, each
// length-prefixed as in CalibrationRowSha256.
std::string ReleaseRowSha256(const std::string& prev_sha256, int64_t seq, const ReleaseRow& release,
                             const std::string& calibration_sha256);

// The head of the store's chains: what an operator keeps outside the
// database (`fluxcal admin anchor`) to find rows removed later together
// with their links, which the chains alone cannot show.
struct ChainHead {
  struct Head {
    std::string serial;
    int version = 0;            // the serial's newest calibration version
    std::string row_sha256;     // its VersionSha256
  };
  std::vector<Head> calibrations;   // by serial (bytewise)
  int64_t release_seq = 0;          // the newest release link (0: none)
  std::string release_serial;
  int release_version = 0;
  std::string release_sha256;
  // SHA-256 over all of the above (ChainHeadDigest): one value to compare.
  std::string digest_sha256;
};
absl::StatusOr<ChainHead> CurrentChainHead(Store& store);
// The newest version of one serial as a head entry (NotFound: none).
absl::StatusOr<ChainHead::Head> SerialHead(Store& store, const std::string& serial);
// The newest release link (ReleaseLinkAt(0)) as head's release_*; head
// unchanged while no release is chained.
absl::Status SetNewestRelease(Store& store, ChainHead* head);
// SHA-256 over "serial\tversion\trow_sha256\n" per calibration head (in
// the order given) and "release\tseq\tserial\tversion\trow_sha256\n".
std::string ChainHeadDigest(const ChainHead& head);

struct ChainReport {
  int chained = 0;                     // versions whose link checks
  int unchained = 0;                   // versions stored before the chain existed (schema < 6)
  // Of `chained`: versions converted from JSON by the v8 migration, checked
  // through their ConversionRow (the JSON their link hashed is not kept).
  int converted = 0;
  int releases_chained = 0;            // releases whose link checks
  // Compared with an anchor: the calibration heads and release head it
  // names that were found as anchored.
  int anchored = 0;
  std::vector<std::string> problems;   // "IPM-1 v3: row changed after it was stored", ...
};
// Recomputes every link of both chains: a calibration row or release
// changed, removed, reordered or inserted around the service shows up as a
// problem naming serial and version (a release also by its seq). A release
// of a version whose verdict is not "pass" is a problem too. With `anchor`
// (a head recorded earlier), each anchored newest version and the anchored
// release head must still be there with the same hash: a row removed
// together with its link after the anchor is named ("IPM-1 v3: removed
// after the anchor"); `anchor_name` says which anchor in the message.
absl::StatusOr<ChainReport> VerifyChains(Store& store, const ChainHead* anchor = nullptr,
                                         const std::string& anchor_name = "the anchor");

// The checks VerifyChains makes, for one version a flasher is about to
// get: released (FailedPrecondition otherwise), verdict "pass"
// (FailedPrecondition), its calibration link and its release link verify
// against the rows and the links before them (DataLoss naming what does
// not: the store was changed behind the service).
absl::Status VerifyReleasedVersion(Store& store, const std::string& serial, int version);

// The migrations of each backend, in order (index k: version k -> k + 1);
// the dialects' data (storage/dialect.h), in every build.
const std::vector<std::string>& SqliteMigrations();
const std::vector<std::string>& PostgresMigrations();

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_STORE_H_
