// The use cases of fluxcal, written once over library calls and the storage
// interface (storage::Store): ingest an HF run, ingest a raw recording, fit
// and judge, export, query, diagnose, fleet statistics. The gRPC server and
// the CLI only translate their inputs to these calls (docs/architecture.md).
#ifndef FLUXCAL_PIPELINE_PIPELINE_H_
#define FLUXCAL_PIPELINE_PIPELINE_H_

#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "absl/status/statusor.h"
#include "diagnosis/diagnose.h"
#include "fitting/calibration.h"
#include "io/recording_set.h"
#include "pipeline/export.h"
#include "pipeline/points.h"
#include "report/report.h"
#include "storage/store.h"
#include "tables/export_rule.h"
#include "tables/tables.h"

namespace fluxcal::pipeline {

// Polled by the long use cases (identification per point, fitting per
// candidate model, diagnosis per refit): true stops the work with
// Cancelled and nothing is stored. A server passes its client's deadline
// and cancellation here as a plain callback; the libraries stay free of RPC.
using CancelledFn = std::function<bool()>;

// Audited writes take a `storage::AuditContext`: the store inserts the
// audit row in the same transaction as the write (storage/store.h).

// --- Ingest.
// As the wire states it (v1::MotorInfo): pole pairs required (1..100),
// rs_ohm and psi_pm_wb 0 when not stated.
struct MotorNominal {
  int pole_pairs = 0;
  double rs_ohm = 0, psi_pm_wb = 0;
};
// One durable transaction. Without `motor` the serial must already be
// known (InvalidArgument otherwise); pole pairs outside 1..100 or no point
// at all is InvalidArgument.
absl::StatusOr<int64_t> IngestHfRun(storage::Store& store, const std::string& serial, const std::string& station,
                                    const std::optional<MotorNominal>& motor,
                                    const std::vector<IdentifiedPoint>& points, int rejected = 0,
                                    const std::string& idempotency_key = "", bool* replayed = nullptr,
                                    const storage::AuditContext* audit = nullptr);

struct IngestRecordingResult {
  int64_t run_id = 0;
  int points = 0;
  std::string sha256;
  int64_t recording_bytes = 0, stored_bytes = 0;
  bool replayed = false;   // the idempotency key named a run stored before
  // What was accepted and stored (for a replay: the run stored before, read
  // back from the store): the run's points (HfPointsSha256) and the
  // recording's files (count, data bytes, RecordingFilesSha256;
  // pipeline/ingest_stream.h).
  std::string points_sha256;
  int files = 0;
  int64_t files_bytes = 0;
  std::string files_sha256;
};
// A recording set held in memory (never written to disk): validated with
// the same reader as `fluxcal`, every file named by the manifest, serial
// equal to `serial`; identified (lsq); points stored with the archived,
// compressed set keyed by its SHA-256. Bad input is InvalidArgument.
// `sha256_before_store` is set before the store write, so that the audit
// detail (formed inside the write's transaction) can name the recording.
absl::StatusOr<IngestRecordingResult> IngestRecording(storage::Store& store, const std::string& serial,
                                                      const std::string& station, const io::RecordingFiles& files,
                                                      const std::string& idempotency_key = "",
                                                      const storage::AuditContext* audit = nullptr,
                                                      const CancelledFn& cancelled = {},
                                                      std::string* sha256_before_store = nullptr);

// --- Fit and judge.
struct FitTolerances {
  double max_rms_relative = 0.02;          // fit residual vs the identified points (a map fit: flux error over its nodes)
  double psi_pm_tolerance_relative = 0.10; // vs the nominal magnet flux
};
// The tolerances a fit request asks for (0: the policy's, FitTolerances'
// defaults). The policy may be tightened, never loosened: a failing run must
// not become "pass" on request. InvalidArgument for a negative or
// non-finite value, or one above the policy's.
absl::StatusOr<FitTolerances> RequestedTolerances(double max_rms_relative, double psi_pm_tolerance_relative);
// A calibration needs a grid: fewer distinct (id_a, iq_a) than this cannot
// determine a flux surface (36 copies of one point must not "pass").
inline constexpr int kMinDistinctOperatingPoints = 6;
// InvalidArgument (field 'points', "nothing stored") for a non-empty run
// with fewer than kMinDistinctOperatingPoints distinct operating points.
absl::Status CheckDistinctOperatingPoints(const std::vector<IdentifiedPoint>& points);
// "pass" or "fail: <reason>" for a fitted calibration, the one place that
// judges one. psi_pm is judged against `nominal_psi_pm_wb`, else against
// the calibration's own nominal (cal.psi_pm_nominal_wb()); with neither
// the verdict is a fail: a calibration missing a fact its verdict depends
// on (pole pairs, the nominal magnet flux) never passes. A nominal of 0
// (a machine without magnets) is not judged relatively.
std::string Verdict(const fit::Calibration& cal, std::optional<double> nominal_psi_pm_wb, size_t points,
                    size_t unreliable, const FitTolerances& tol);
// Fits the latest run of `serial` and stores calibration version n+1. A
// run ingested with its raw recording (IngestRecording) is fitted from the
// stored set through FitDataFromSet, the function `fluxcal fit SET` uses,
// so both give the same calibration (and standard errors) for the same
// set; a run of HF results only is fitted from its points
// (FitDataFromPoints). `audit` is inserted with the version (its detail,
// when unset, "version N (model): verdict"); `cancelled` stops the fit
// before anything is stored.
absl::StatusOr<storage::CalibrationRow> FitSerial(storage::Store& store, const std::string& serial,
                                                  const std::string& model, const FitTolerances& tol,
                                                  const storage::AuditContext* audit = nullptr,
                                                  const CancelledFn& cancelled = {});

// --- Read.
// A calibration JSON file (fluxcal fit's output), and one already parsed.
absl::StatusOr<fit::Calibration> LoadCalibrationFile(const std::string& path);
absl::StatusOr<fit::Calibration> ParseCalibrationJson(const nlohmann::json& j);
// Where a predicted point lies, as the API and `fluxcal query` name it
// ("measured", "by_symmetry", "extrapolated").
const char* FluxRegionName(fit::Region region);
// A stored row's calibration JSON parsed (DataLoss when corrupt).
absl::StatusOr<fit::Calibration> ParseStoredCalibration(const storage::CalibrationRow& row);
absl::StatusOr<fit::Calibration> LoadCalibration(storage::Store& store, const std::string& serial, int version);

struct QueryResult {
  int version = 0;
  std::vector<fit::FluxPrediction> values;
};
absl::StatusOr<QueryResult> QueryFlux(storage::Store& store, const std::string& serial, int version,
                                      const std::vector<std::pair<double, double>>& points);

// --- Records: what the store holds about a serial, as the service's reads
// return it.
// A stored version with its JSON view: calibration_json holds the JSON
// (fluxcal.calibration.v1) of the binary model the row stores
// (pipeline/calibration_codec.h), or the JSON as stored for a version the
// v8 migration left as JSON. FitSerial and StoreDiagnosedCalibration return
// this too: the service's replies and `fluxcal query` show JSON.
absl::StatusOr<storage::CalibrationRow> StoredRowView(storage::Store& store, const std::string& serial, int version);
// Calibration `version` of `serial` (0: the latest) as stored, with its
// JSON view (StoredRowView).
absl::StatusOr<storage::CalibrationRow> GetCalibrationRecord(storage::Store& store, const std::string& serial,
                                                             int version);
// One page of the motor list: at most `page_size` motors from `offset`
// (serials starting with `prefix`; `only_failed`: latest verdict not
// "pass"), and the offset of the next page when there is one.
struct MotorPage {
  std::vector<storage::MotorSummaryRow> motors;
  std::optional<int> next_offset;
};
absl::StatusOr<MotorPage> ListMotorsPage(storage::Store& store, const std::string& prefix, bool only_failed,
                                         int offset, int page_size);
// What happened to a serial (runs, versions, releases), oldest first, and
// its audit trail.
absl::StatusOr<std::vector<storage::HistoryRow>> MotorHistory(storage::Store& store, const std::string& serial);
absl::StatusOr<std::vector<storage::AuditRow>> AuditTrail(storage::Store& store, const std::string& serial);

// --- Release.
// Releases calibration `version` of `serial` for flashing, by
// `released_by` (its release chain link and `audit` in the same
// transaction; storage::Store::Release says what is refused).
absl::Status ReleaseVersion(storage::Store& store, const std::string& serial, int version,
                            const std::string& released_by, const storage::AuditContext* audit = nullptr);

// Export (ExportResult, ExportCalibration, ExportTable): pipeline/export.h.

// The version a flashing station gets (ExportTable for the flasher role):
// version 0 is the newest released one (FailedPrecondition when there is
// none), an explicit version must be released. Either is re-checked now,
// at export time, by storage::VerifyReleasedVersion: released and verdict
// "pass" (FailedPrecondition otherwise), its calibration row and release
// row still what their chain links say, and the links still chained
// (DataLoss otherwise: the store was changed behind the service).
absl::StatusOr<int> FlashableVersion(storage::Store& store, const std::string& serial, int version);

// The fleet at one operating point: one type (report::FleetPoint, which the
// page's fleet section takes as it is), converted only at the proto edge
// (the service's FleetStatistics, `fluxcal report --server`).
using FleetPoint = report::FleetPoint;
// The operating points (id_a, iq_a) and outlier threshold (standard
// deviations) when a caller names none: the FleetStatistics RPC's defaults
// and the report's fleet section, so both show the same comparison.
inline constexpr std::pair<double, double> kDefaultFleetPointsA[] = {{-20, 40}, {-60, 80}, {0, 100}};
inline constexpr double kDefaultOutlierSigma = 3.0;
// `cancelled` is polled per parsed calibration: a large fleet of spline
// calibrations takes seconds to parse.
absl::StatusOr<std::vector<FleetPoint>> FleetStatistics(storage::Store& store,
                                                        const std::vector<std::pair<double, double>>& points,
                                                        double outlier_sigma, const CancelledFn& cancelled = {});

// A stored raw recording (by SHA-256), unpacked and read in memory.
absl::StatusOr<io::RecordingSet> LoadStoredRecording(storage::Store& store, const std::string& sha256);
// Diagnosis of the serial's latest stored raw recording, unpacked in memory.
// The diagnosed model of `report` (diag::DiagnosedCalibration) stored as a
// new calibration version of `serial`: its JSON marked with the findings
// (diag::MarkedCalibrationJson), judged by Verdict against the motor's
// nominal psi_pm, linked to the latest run, audited with `audit` in the
// same transaction. A version is stored whole or not at all.
absl::StatusOr<storage::CalibrationRow> StoreDiagnosedCalibration(storage::Store& store, const std::string& serial,
                                                                  const diag::DiagnosisReport& report,
                                                                  const FitTolerances& tol,
                                                                  const storage::AuditContext* audit);

absl::StatusOr<diag::DiagnosisReport> DiagnoseStored(storage::Store& store, const std::string& serial,
                                                     const CancelledFn& cancelled = {});

// --- Whole stores (fluxcal admin).
// SHA-256 over a canonical dump of everything stored (motors, runs with
// their idempotency keys, points, recordings, calibrations, releases, the
// audit trail, the calibration and release chains; ids, versions,
// timestamps and hashes included): equal hashes mean equal content,
// whatever the backend.
absl::StatusOr<std::string> ContentHash(storage::Store& store);
struct MigrateResult {
  int motors = 0, runs = 0, points = 0, recordings = 0, calibrations = 0;
  int releases = 0, audit_rows = 0, chain_links = 0, release_links = 0;
  std::string content_sha256;   // equal on both sides
};
// Copies `from` into the empty store `to` and verifies both content hashes.
absl::StatusOr<MigrateResult> Migrate(storage::Store& from, storage::Store& to);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_PIPELINE_H_
