#include "pipeline/pipeline.h"

#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <set>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_format.h"
#include "nlohmann/json.hpp"
#include "pipeline/calibration_codec.h"
#include "pipeline/ingest_stream.h"
#include "pipeline/recording_archive.h"
#include "io/sha256.h"

namespace fluxcal::pipeline {

// ---------------------------------------------------------------- points

bool FromIdentification(const ident::HfPointResult& r, IdentifiedPoint* h) {
  if (!std::isfinite(r.ld_h) || !std::isfinite(r.id_a)) return false;   // identification_failed
  *h = IdentifiedPoint{};
  h->point_id = r.point; h->id_a = r.id_a; h->iq_a = r.iq_a; h->speed_rpm = r.speed_rpm;
  h->ld_h = r.ld_h; h->lq_h = r.lq_h;
  if (r.has_ldq) h->ldq_h = r.ldq_h;
  h->ld_h_std = r.ld_h_std; h->lq_h_std = r.lq_h_std; h->ldq_h_std = r.ldq_h_std;
  h->temperature_c = r.temperature_c; h->reliable = r.reliable;
  return true;
}

fit::InductanceObservation ToObservation(const IdentifiedPoint& p) {
  fit::InductanceObservation o;
  o.id_a = p.id_a; o.iq_a = p.iq_a; o.ldd_h = p.ld_h; o.lqq_h = p.lq_h; o.ldq_h = p.ldq_h;
  o.ldd_h_std = p.ld_h_std; o.lqq_h_std = p.lq_h_std; o.ldq_h_std = p.ldq_h_std;
  return o;
}

v1::HfPoint ToProto(const IdentifiedPoint& r) {
  v1::HfPoint p;
  p.set_point_id(r.point_id); p.set_id_a(r.id_a); p.set_iq_a(r.iq_a); p.set_speed_rpm(r.speed_rpm);
  p.set_ld_h(r.ld_h); p.set_lq_h(r.lq_h);
  if (r.ldq_h) p.set_ldq_h(*r.ldq_h);
  p.set_ld_h_std(r.ld_h_std); p.set_lq_h_std(r.lq_h_std); p.set_ldq_h_std(r.ldq_h_std);
  p.set_temperature_c(r.temperature_c); p.set_reliable(r.reliable);
  return p;
}

IdentifiedPoint FromProto(const v1::HfPoint& p) {
  IdentifiedPoint r;
  r.point_id = p.point_id();
  r.id_a = p.id_a(); r.iq_a = p.iq_a(); r.speed_rpm = p.speed_rpm();
  r.ld_h = p.ld_h(); r.lq_h = p.lq_h();
  if (p.has_ldq_h()) r.ldq_h = p.ldq_h();
  r.ld_h_std = p.ld_h_std(); r.lq_h_std = p.lq_h_std(); r.ldq_h_std = p.ldq_h_std();
  r.temperature_c = p.temperature_c();
  r.reliable = p.reliable();
  return r;
}

absl::StatusOr<IdentifiedSet> IdentifySet(const io::RecordingSet& set, const ident::IdentifyOptions& options) {
  auto ids = ident::IdentifySet(set, options);
  if (!ids.ok()) return ids.status();
  IdentifiedSet out;
  out.results = std::move(*ids);
  for (const auto& r : out.results) {
    IdentifiedPoint p;
    if (FromIdentification(r, &p)) {
      out.points.push_back(std::move(p));
    } else {
      out.failures.push_back(absl::StrCat(r.point, ": ", r.failure));
    }
  }
  return out;
}

fit::FitData FitDataFromPoints(const storage::MotorRow& motor, const std::vector<IdentifiedPoint>& points) {
  fit::FitData d;
  d.serial = motor.serial;
  d.pole_pairs = motor.pole_pairs;
  // The store keeps 0 for a value the station did not state (the wire's unset).
  if (motor.rs_ohm > 0) d.rs_ohm = motor.rs_ohm;
  if (motor.psi_pm_wb > 0) d.psi_pm_prior_wb = motor.psi_pm_wb;
  for (const auto& p : points) d.inductances.push_back(ToObservation(p));
  return d;
}

absl::StatusOr<fit::FitData> FitDataFromSet(const io::RecordingSet& set, const ident::IdentifyOptions& options) {
  auto ids = ident::IdentifySet(set, options);
  if (!ids.ok()) return ids.status();
  return fit::FitDataFromRecording(set, *ids);
}

// ---------------------------------------------------------------- ingest

namespace {

// The raw recording a run of `serial` was ingested with (NotFound: a run
// of HF results only).
absl::StatusOr<std::string> RecordingShaOfRun(storage::Store& store, const std::string& serial, int64_t run_id) {
  auto history = store.History(serial);
  if (!history.ok()) return history.status();
  for (const auto& h : *history) {
    if (h.run_id == run_id && h.kind == "recording" && !h.detail.empty()) return h.detail;
  }
  return absl::NotFoundError(absl::StrCat("run ", run_id, " of '", serial, "' has no raw recording"));
}

}  // namespace

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

// ---------------------------------------------------------------- fit

std::string Verdict(const fit::Calibration& cal, std::optional<double> nominal, size_t points, size_t unreliable,
                    const FitTolerances& tol) {
  // Facts first: without them no other check means anything.
  if (cal.pole_pairs() < 1) return "fail: pole pairs unknown";
  if (!nominal) nominal = cal.psi_pm_nominal_wb();
  if (!nominal) {
    return "fail: nominal psi_pm unknown (no motor.psi_pm_wb in the manifest or from the station, no "
           "--psi-pm-wb): the fitted magnet flux cannot be judged";
  }
  const double nominal_psi_pm_wb = *nominal;
  if (!cal.summary.usable) return "fail: fit did not converge";
  if (cal.summary.rms_relative > tol.max_rms_relative) {
    return absl::StrFormat("fail: fit residual %.2f %% above %.2f %%", 100 * cal.summary.rms_relative,
                           100 * tol.max_rms_relative);
  }
  // A map fit (flux nodes, no inductances) is judged by its flux error over
  // the map's nodes, against the same tolerance.
  if (cal.summary.flux_nodes > 0 && !(cal.summary.flux_rms_relative <= tol.max_rms_relative)) {
    return absl::StrFormat("fail: flux error against the map %.2f %% above %.2f %%",
                           100 * cal.summary.flux_rms_relative, 100 * tol.max_rms_relative);
  }
  if (nominal_psi_pm_wb > 0 && std::abs(cal.psi_pm_wb() / nominal_psi_pm_wb - 1) > tol.psi_pm_tolerance_relative) {
    return absl::StrFormat("fail: psi_pm %.5g Wb deviates %.1f %% from nominal", cal.psi_pm_wb(),
                           100 * (cal.psi_pm_wb() / nominal_psi_pm_wb - 1));
  }
  if (unreliable * 2 > points) {
    // Points near a phase-current zero crossing are flagged by design (the
    // paper's Sec. 3.3); only a majority of unreliable points fails a motor.
    return absl::StrFormat("fail: %zu of %zu points flagged unreliable", unreliable, points);
  }
  return "pass";
}

absl::StatusOr<storage::CalibrationRow> FitSerial(storage::Store& store, const std::string& serial,
                                                  const std::string& model, const FitTolerances& tol,
                                                  const storage::AuditContext* audit, const CancelledFn& cancelled) {
  auto motor = store.GetMotor(serial);
  if (!motor.ok()) return motor.status();
  int64_t run_id = 0;
  auto pts = store.LatestRunPoints(serial, &run_id);
  if (!pts.ok()) return pts.status();
  size_t unreliable = 0;
  for (const auto& p : *pts) unreliable += p.reliable ? 0 : 1;
  // A run that carries its raw recording is fitted from the set, through
  // FitDataFromSet as `fluxcal fit SET` does: the steady-state rows and the
  // drive data then constrain the surfaces here as they do locally. From
  // the stored points alone psi_d is pinned only by the magnet-flux prior,
  // and its standard error came out an order of magnitude larger than the
  // local fit's for the same set.
  auto recording_sha = RecordingShaOfRun(store, serial, run_id);
  if (!recording_sha.ok() && recording_sha.status().code() != absl::StatusCode::kNotFound) {
    return recording_sha.status();
  }
  fit::FitData d;
  if (recording_sha.ok()) {
    auto set = LoadStoredRecording(store, *recording_sha);
    if (!set.ok()) return set.status();
    ident::IdentifyOptions idopt;
    idopt.cancelled = cancelled;
    auto fd = FitDataFromSet(*set, idopt);
    if (!fd.ok()) return fd.status();
    d = std::move(*fd);
  } else {
    d = FitDataFromPoints(*motor, *pts);
  }
  d.serial = serial;
  fit::FitOptions fo;
  fo.model = model.empty() ? "auto" : model;
  fo.cancelled = cancelled;
  auto cal = fit::Fit(d, fo);
  if (!cal.ok()) return cal.status();
  // The last chance to stop: after this the version is stored whole.
  if (cancelled && cancelled()) return absl::CancelledError("fit: cancelled by the caller before storing");
  storage::CalibrationRow row;
  row.serial = serial;
  row.run_id = run_id;
  row.model = cal->family().Name();
  row.psi_pm_wb = cal->psi_pm_wb();
  row.rms_relative = cal->summary.rms_relative;
  row.verdict = Verdict(*cal, motor->psi_pm_wb > 0 ? std::optional<double>(motor->psi_pm_wb) : std::nullopt,
                        pts->size(), unreliable, tol);
  // Stored as the binary model (pipeline/calibration_codec.h); the JSON is
  // its view (StoredRowView).
  row.model_pb = EncodeCalibration(*cal);
  // An audit row without its own detail says what was stored.
  storage::AuditContext fit_audit;
  if (audit != nullptr) {
    fit_audit = *audit;
    if (!fit_audit.detail) {
      fit_audit.detail = [model = row.model, verdict = row.verdict](int64_t version, bool) {
        return absl::StrCat("version ", version, " (", model, "): ", verdict);
      };
    }
  }
  auto version = store.AddCalibration(row, audit != nullptr ? &fit_audit : nullptr);
  if (!version.ok()) return version.status();
  return StoredRowView(store, serial, *version);
}

// ---------------------------------------------------------------- read

namespace {

// Parsed calibrations, by serial and version, keyed on the version's chain
// hash (storage::CalibrationRowSha256: SHA-256 over every stored field).
// Parsing dominated a query once calibrations carried a smoothing spline's
// covariance as ~0.5 MB of JSON (QueryFlux p50 went from 0.7 to 8 ms);
// since schema v8 a version is ~40 kB of binary that decodes in ~0.3 ms
// (docs/performance.md), and a hit still saves moving it out of the
// database: stored rows never change (append-only, hash-chained), so a hit
// needs only the tiny chain link. Rows from before the chain (schema < 6)
// are compared by their content instead. At most kCachedCalibrations entries, the least recently
// used evicted.
constexpr size_t kCachedCalibrations = 64;
struct CachedCalibration {
  std::string content;   // chain hash, or the JSON text for unchained rows
  std::shared_ptr<const fit::Calibration> cal;
  uint64_t last_use = 0;
};
std::mutex cache_mu;
std::map<std::pair<std::string, int>, CachedCalibration>& Cache() {
  static auto* c = new std::map<std::pair<std::string, int>, CachedCalibration>;
  return *c;
}
uint64_t cache_tick = 0;

std::optional<fit::Calibration> CacheLookup(const std::pair<std::string, int>& key, const std::string& content) {
  std::lock_guard<std::mutex> lock(cache_mu);
  auto it = Cache().find(key);
  if (it == Cache().end() || it->second.content != content) return std::nullopt;
  it->second.last_use = ++cache_tick;
  return *it->second.cal;
}

void CacheStore(const std::pair<std::string, int>& key, std::string content, const fit::Calibration& cal) {
  std::lock_guard<std::mutex> lock(cache_mu);
  auto& cache = Cache();
  if (cache.size() >= kCachedCalibrations && !cache.count(key)) {
    auto oldest = cache.begin();
    for (auto it = cache.begin(); it != cache.end(); ++it)
      if (it->second.last_use < oldest->second.last_use) oldest = it;
    cache.erase(oldest);
  }
  cache[key] = {std::move(content), std::make_shared<const fit::Calibration>(cal), ++cache_tick};
}

}  // namespace

absl::StatusOr<fit::Calibration> LoadCalibration(storage::Store& store, const std::string& serial, int version) {
  // The chain link names the version and its content hash without moving
  // the row; the prefix keeps two stores' hashes apart in one process.
  auto link = store.ChainLink(serial, version);
  if (link.ok()) {
    const std::string content = absl::StrCat(store.Backend(), ":", link->row_sha256);
    if (auto hit = CacheLookup({serial, link->version}, content)) return *hit;
  }
  auto row = store.GetCalibration(serial, version);
  if (!row.ok()) return row.status();
  const bool chained = link.ok() && link->version == row->version;
  const std::string content =
      chained ? absl::StrCat(store.Backend(), ":", link->row_sha256)
              : (row->model_pb.empty() ? row->calibration_json : row->model_pb);
  if (!chained) {
    if (auto hit = CacheLookup({serial, row->version}, content)) return *hit;
  }
  auto parsed = ParseStoredCalibration(*row);
  if (!parsed.ok()) return parsed.status();
  CacheStore({serial, row->version}, content, *parsed);
  return *parsed;
}

absl::StatusOr<FitTolerances> RequestedTolerances(double max_rms_relative, double psi_pm_tolerance_relative) {
  FitTolerances tol;
  if (max_rms_relative < 0 || !std::isfinite(max_rms_relative) || psi_pm_tolerance_relative < 0 ||
      !std::isfinite(psi_pm_tolerance_relative)) {
    return absl::InvalidArgumentError("max_rms_relative, psi_pm_tolerance_relative: must be >= 0");
  }
  if (max_rms_relative > tol.max_rms_relative || psi_pm_tolerance_relative > tol.psi_pm_tolerance_relative) {
    return absl::InvalidArgumentError(
        absl::StrFormat("max_rms_relative, psi_pm_tolerance_relative: may only tighten the server policy (%g, %g)",
                        tol.max_rms_relative, tol.psi_pm_tolerance_relative));
  }
  if (max_rms_relative > 0) tol.max_rms_relative = max_rms_relative;
  if (psi_pm_tolerance_relative > 0) tol.psi_pm_tolerance_relative = psi_pm_tolerance_relative;
  return tol;
}

absl::Status CheckDistinctOperatingPoints(const std::vector<IdentifiedPoint>& points) {
  std::set<std::pair<double, double>> distinct;
  for (const auto& r : points) distinct.insert({r.id_a, r.iq_a});
  if (!points.empty() && static_cast<int>(distinct.size()) < kMinDistinctOperatingPoints) {
    return absl::InvalidArgumentError(absl::StrCat(
        "points: ", distinct.size(), " distinct operating points (id_a, iq_a); a calibration needs at least ",
        kMinDistinctOperatingPoints, "; nothing stored"));
  }
  return absl::OkStatus();
}

absl::StatusOr<fit::Calibration> LoadCalibrationFile(const std::string& path) { return fit::LoadCalibrationFile(path); }

absl::StatusOr<fit::Calibration> ParseCalibrationJson(const nlohmann::json& j) { return fit::Calibration::FromJson(j); }

const char* FluxRegionName(fit::Region region) { return fit::RegionName(region); }

absl::StatusOr<fit::Calibration> ParseStoredCalibration(const storage::CalibrationRow& stored) {
  if (!stored.model_pb.empty()) {
    auto cal = DecodeCalibration(stored.model_pb);
    if (!cal.ok()) {
      return absl::DataLossError(
          absl::StrCat("stored calibration of ", stored.serial, " is corrupt: ", cal.status().message()));
    }
    cal->version = stored.version;   // the version it is stored under
    return cal;
  }
  const storage::CalibrationRow* row = &stored;
  const std::string& serial = stored.serial;
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(row->calibration_json);
  } catch (const nlohmann::json::exception& e) {
    return absl::DataLossError(absl::StrCat("stored calibration of ", serial, " is corrupt: ", e.what()));
  }
  // The stored JSON carries the version it is stored under.
  j["version"] = row->version;
  return fit::Calibration::FromJson(j);
}

absl::StatusOr<QueryResult> QueryFlux(storage::Store& store, const std::string& serial, int version,
                                      const std::vector<std::pair<double, double>>& points) {
  auto cal = LoadCalibration(store, serial, version);
  if (!cal.ok()) return cal.status();
  QueryResult out;
  out.version = cal->version;
  out.values.reserve(points.size());
  for (const auto& [id, iq] : points) out.values.push_back(cal->Predict(id, iq));
  return out;
}

absl::StatusOr<storage::CalibrationRow> StoredRowView(storage::Store& store, const std::string& serial, int version) {
  auto row = store.GetCalibration(serial, version);
  if (!row.ok()) return row.status();
  auto text = StoredCalibrationJsonText(*row);
  if (!text.ok()) return text.status();
  row->calibration_json = std::move(*text);
  return row;
}

absl::StatusOr<storage::CalibrationRow> GetCalibrationRecord(storage::Store& store, const std::string& serial,
                                                             int version) {
  return StoredRowView(store, serial, version);
}

absl::StatusOr<MotorPage> ListMotorsPage(storage::Store& store, const std::string& prefix, bool only_failed,
                                         int offset, int page_size) {
  // One row more than the page: whether a next page exists, in one query.
  auto rows = store.ListMotors(prefix, only_failed, offset, page_size + 1);
  if (!rows.ok()) return rows.status();
  MotorPage page;
  if (static_cast<int>(rows->size()) > page_size) {
    rows->resize(page_size);
    page.next_offset = offset + page_size;
  }
  page.motors = std::move(*rows);
  return page;
}

absl::StatusOr<std::vector<storage::HistoryRow>> MotorHistory(storage::Store& store, const std::string& serial) {
  return store.History(serial);
}

absl::StatusOr<std::vector<storage::AuditRow>> AuditTrail(storage::Store& store, const std::string& serial) {
  return store.AuditOf(serial);
}

absl::Status ReleaseVersion(storage::Store& store, const std::string& serial, int version,
                            const std::string& released_by, const storage::AuditContext* audit) {
  return store.Release(serial, version, released_by, audit);
}

absl::StatusOr<int> FlashableVersion(storage::Store& store, const std::string& serial, int version) {
  if (version == 0) {
    auto v = store.LatestReleasedVersion(serial);
    if (!v.ok()) return v.status();
    if (*v == 0) {
      return absl::FailedPreconditionError(
          absl::StrCat("serial '", serial, "' has no released calibration (fluxcal release)"));
    }
    version = *v;
  }
  if (auto s = storage::VerifyReleasedVersion(store, serial, version); !s.ok()) return s;
  return version;
}

absl::StatusOr<std::vector<FleetPoint>> FleetStatistics(storage::Store& store,
                                                        const std::vector<std::pair<double, double>>& points,
                                                        double outlier_sigma, const CancelledFn& cancelled) {
  auto rows = store.LatestCalibrations();
  if (!rows.ok()) return rows.status();
  std::vector<std::pair<std::string, fit::Calibration>> cals;
  for (const auto& r : *rows) {
    if (cancelled && cancelled()) return absl::CancelledError("fleet statistics: cancelled by the caller");
    auto c = ParseStoredCalibration(r);
    if (c.ok()) cals.push_back({r.serial, std::move(*c)});
  }
  std::vector<FleetPoint> out;
  for (const auto& [id, iq] : points) {
    FleetPoint fp;
    fp.id_a = id;
    fp.iq_a = iq;
    fp.serials = static_cast<int>(cals.size());
    std::vector<fit::FluxPrediction> p;
    for (const auto& c : cals) p.push_back(c.second.Predict(id, iq));
    auto stats = [&](auto get, double* mean, double* sd) {
      double s = 0, s2 = 0;
      for (const auto& x : p) { s += get(x); s2 += get(x) * get(x); }
      const double n = std::max<size_t>(1, p.size());
      *mean = s / n;
      *sd = p.size() > 1 ? std::sqrt(std::max(0.0, (s2 - s * s / n) / (n - 1))) : 0.0;
    };
    stats([](const fit::FluxPrediction& x) { return x.ldd_h; }, &fp.ldd_h_mean, &fp.ldd_h_std);
    stats([](const fit::FluxPrediction& x) { return x.lqq_h; }, &fp.lqq_h_mean, &fp.lqq_h_std);
    stats([](const fit::FluxPrediction& x) { return x.psi_d_wb; }, &fp.psi_d_wb_mean, &fp.psi_d_wb_std);
    stats([](const fit::FluxPrediction& x) { return x.torque_nm; }, &fp.torque_nm_mean, &fp.torque_nm_std);
    // Outliers: any quantity more than outlier_sigma standard deviations from
    // the fleet mean (leave-one-out would be better for tiny fleets).
    for (size_t k = 0; k < p.size(); ++k) {
      auto z = [&](double v, double m, double s) { return s > 0 ? std::abs(v - m) / s : 0.0; };
      if (z(p[k].ldd_h, fp.ldd_h_mean, fp.ldd_h_std) > outlier_sigma || z(p[k].lqq_h, fp.lqq_h_mean, fp.lqq_h_std) > outlier_sigma ||
          z(p[k].torque_nm, fp.torque_nm_mean, fp.torque_nm_std) > outlier_sigma) {
        fp.outliers.push_back(cals[k].first);
      }
    }
    out.push_back(fp);
  }
  return out;
}

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
  storage::CalibrationRow row;
  row.serial = serial;
  row.run_id = run_id;
  row.model = cal->family().Name();
  row.psi_pm_wb = cal->psi_pm_wb();
  row.rms_relative = cal->summary.rms_relative;
  row.verdict = Verdict(*cal, motor->psi_pm_wb > 0 ? std::optional<double>(motor->psi_pm_wb) : std::nullopt,
                        report.corrected_data.inductances.size(), 0, tol);
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

// ---------------------------------------------------------------- admin

absl::StatusOr<std::string> ContentHash(storage::Store& store) {
  std::string dump;
  auto d = [&](double v) { absl::StrAppendFormat(&dump, "%.17g\t", v); };
  auto motors = store.AllMotors();
  if (!motors.ok()) return motors.status();
  for (const auto& m : *motors) {
    absl::StrAppend(&dump, "motor\t", m.serial, "\t", m.pole_pairs, "\t");
    d(m.rs_ohm); d(m.psi_pm_wb);
    absl::StrAppend(&dump, m.created_utc, "\n");
  }
  auto runs = store.AllRuns();
  if (!runs.ok()) return runs.status();
  for (const auto& r : *runs) {
    absl::StrAppend(&dump, "run\t", r.run_id, "\t", r.serial, "\t", r.station, "\t", r.kind, "\t", r.recording_sha256,
                    "\t", r.created_utc, "\t", r.idempotency_key, "\n");
    if (!r.recording_sha256.empty()) {
      auto rec = store.GetRecordingRow(r.recording_sha256);
      if (!rec.ok()) return rec.status();
      const std::string_view z(reinterpret_cast<const char*>(rec->zlib_data.data()), rec->zlib_data.size());
      absl::StrAppend(&dump, "recording\t", rec->size_bytes, "\t", io::Sha256Hex(z), "\n");
    }
    auto pts = store.RunPoints(r.run_id);
    if (!pts.ok()) return pts.status();
    for (const auto& p : *pts) {
      absl::StrAppend(&dump, "point\t", p.point_id, "\t");
      for (double v : {p.id_a, p.iq_a, p.speed_rpm, p.ld_h, p.lq_h}) d(v);
      if (p.ldq_h) d(*p.ldq_h); else dump += "null\t";
      for (double v : {p.ld_h_std, p.lq_h_std, p.ldq_h_std, p.temperature_c}) d(v);
      absl::StrAppend(&dump, p.reliable ? 1 : 0, "\n");
    }
  }
  auto cals = store.AllCalibrations();
  if (!cals.ok()) return cals.status();
  for (const auto& c : *cals) {
    absl::StrAppend(&dump, "calibration\t", c.serial, "\t", c.version, "\t", c.run_id, "\t", c.created_utc, "\t",
                    c.model, "\t");
    d(c.psi_pm_wb); d(c.rms_relative);
    // The content as stored: the binary model, or the JSON of a version
    // the v8 migration left as JSON.
    absl::StrAppend(&dump, c.verdict, "\t", io::Sha256Hex(c.calibration_json), "\t", io::Sha256Hex(c.model_pb), "\n");
  }
  // Text fields are length-prefixed: free text (audit detail) may hold tabs.
  auto t = [&](const std::string& v) { absl::StrAppend(&dump, v.size(), ":", v, "\t"); };
  auto releases = store.AllReleases();
  if (!releases.ok()) return releases.status();
  for (const auto& r : *releases) {
    dump += "release\t";
    t(r.serial); absl::StrAppend(&dump, r.version, "\t"); t(r.released_by); t(r.released_utc);
    dump += "\n";
  }
  auto audit = store.AllAudit();
  if (!audit.ok()) return audit.status();
  for (const auto& a : *audit) {
    absl::StrAppend(&dump, "audit\t", a.id, "\t");
    for (const auto* v : {&a.utc, &a.identity, &a.role, &a.peer, &a.request_id, &a.rpc, &a.serial, &a.detail}) t(*v);
    dump += "\n";
  }
  auto chain = store.AllChainRows();
  if (!chain.ok()) return chain.status();
  for (const auto& l : *chain) {
    dump += "link\t";
    t(l.serial); absl::StrAppend(&dump, l.version, "\t"); t(l.prev_sha256); t(l.row_sha256);
    dump += "\n";
  }
  auto release_chain = store.AllReleaseLinks();
  if (!release_chain.ok()) return release_chain.status();
  for (const auto& l : *release_chain) {
    absl::StrAppend(&dump, "release_link\t", l.seq, "\t");
    t(l.serial); absl::StrAppend(&dump, l.version, "\t"); t(l.calibration_sha256); t(l.prev_sha256); t(l.row_sha256);
    dump += "\n";
  }
  return io::Sha256Hex(dump);
}

absl::StatusOr<MigrateResult> Migrate(storage::Store& from, storage::Store& to) {
  if (auto m = to.AllMotors(); !m.ok()) {
    return m.status();
  } else if (!m->empty()) {
    return absl::FailedPreconditionError("migrate: the target store is not empty");
  }
  MigrateResult out;
  auto motors = from.AllMotors();
  if (!motors.ok()) return motors.status();
  for (const auto& m : *motors) {
    if (auto s = to.ImportMotor(m); !s.ok()) return s;
    ++out.motors;
  }
  auto runs = from.AllRuns();
  if (!runs.ok()) return runs.status();
  std::set<std::string> recordings;
  for (const auto& r : *runs) {
    auto pts = from.RunPoints(r.run_id);
    if (!pts.ok()) return pts.status();
    std::optional<storage::RecordingRow> rec;
    if (!r.recording_sha256.empty() && recordings.insert(r.recording_sha256).second) {
      auto x = from.GetRecordingRow(r.recording_sha256);
      if (!x.ok()) return x.status();
      rec = std::move(*x);
      ++out.recordings;
    }
    if (auto s = to.ImportRun(r, *pts, rec ? &*rec : nullptr); !s.ok()) return s;
    ++out.runs;
    out.points += static_cast<int>(pts->size());
  }
  auto cals = from.AllCalibrations();
  if (!cals.ok()) return cals.status();
  for (const auto& c : *cals) {
    if (auto s = to.ImportCalibration(c); !s.ok()) return s;
    ++out.calibrations;
  }
  // Releases, the audit trail and the chain links as stored (ids, times and
  // hashes kept): the copy verifies as the source did.
  auto releases = from.AllReleases();
  if (!releases.ok()) return releases.status();
  auto audit = from.AllAudit();
  if (!audit.ok()) return audit.status();
  auto chain = from.AllChainRows();
  if (!chain.ok()) return chain.status();
  auto release_chain = from.AllReleaseLinks();
  if (!release_chain.ok()) return release_chain.status();
  if (auto s = to.ImportTrail(*releases, *audit, *chain, *release_chain); !s.ok()) return s;
  auto conversions = from.AllConversions();
  if (!conversions.ok()) return conversions.status();
  if (auto s = to.ImportConversions(*conversions); !s.ok()) return s;
  out.releases = static_cast<int>(releases->size());
  out.audit_rows = static_cast<int>(audit->size());
  out.chain_links = static_cast<int>(chain->size());
  out.release_links = static_cast<int>(release_chain->size());
  auto a = ContentHash(from);
  if (!a.ok()) return a.status();
  auto b = ContentHash(to);
  if (!b.ok()) return b.status();
  if (*a != *b) {
    return absl::DataLossError(absl::StrCat("migrate: content hashes differ after the copy (source ", *a,
                                            ", target ", *b, ")"));
  }
  out.content_sha256 = *a;
  return out;
}

}  // namespace fluxcal::pipeline
