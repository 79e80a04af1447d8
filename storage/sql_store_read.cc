// SqlStore, part 2: every read, and the imports `fluxcal admin migrate`
// copies a store with. Written once for every backend; the only dialect
// data used here is the bytewise ordering of serials and the identity
// catch-up after an import (storage/dialect.h).
#include "absl/strings/str_cat.h"
#include "storage/sql_store.h"

namespace fluxcal::storage {
namespace {

constexpr char kAuditCols[] = "SELECT id, utc, identity, role, peer, request_id, rpc, serial, detail FROM audit ";
constexpr char kReleaseCols[] = "SELECT serial, version, released_by, released_utc FROM releases ";
constexpr char kReleaseLinkCols[] =
    "SELECT seq, serial, version, calibration_sha256, prev_sha256, row_sha256 FROM release_chain ";
constexpr char kConversionCols[] =
    "SELECT serial, version, json_sha256, row_sha256, converted_utc FROM calibration_conversions ";
constexpr char kPointsOfRun[] =
    "SELECT point_id, id_a, iq_a, speed_rpm, ld_h, lq_h, ldq_h, ld_h_std, lq_h_std, ldq_h_std, temperature_c, "
    "reliable, hf_flux_radius_wb FROM hf_points WHERE run_id = ? ORDER BY idx";

AuditRow ReadAudit(const SqlRow& r) {
  return {r.Int(0), r.Text(1), r.Text(2), r.Text(3), r.Text(4), r.Text(5), r.Text(6), r.Text(7), r.Text(8)};
}
ReleaseRow ReadRelease(const SqlRow& r) { return {r.Text(0), r.Int32(1), r.Text(2), r.Text(3)}; }
ReleaseLinkRow ReadReleaseLink(const SqlRow& r) {
  return {r.Int(0), r.Text(1), r.Int32(2), r.Text(3), r.Text(4), r.Text(5)};
}
ConversionRow ReadConversion(const SqlRow& r) { return {r.Text(0), r.Int32(1), r.Text(2), r.Text(3), r.Text(4)}; }
HfPointRow ReadPoint(const SqlRow& r) {
  HfPointRow h;
  h.point_id = r.Text(0);
  h.id_a = r.Double(1); h.iq_a = r.Double(2); h.speed_rpm = r.Double(3);
  h.ld_h = r.Double(4); h.lq_h = r.Double(5);
  if (!r.IsNull(6)) h.ldq_h = r.Double(6);
  h.ld_h_std = r.Double(7); h.lq_h_std = r.Double(8); h.ldq_h_std = r.Double(9);
  h.temperature_c = r.Double(10); h.reliable = r.Int(11) != 0;
  if (!r.IsNull(12)) h.hf_flux_radius_wb = r.Double(12);
  return h;
}

// All rows of a query, each read with `read`.
template <typename Read>
auto All(SqlSource& s, const std::string& sql, const std::vector<SqlValue>& params, Read read)
    -> absl::StatusOr<std::vector<decltype(read(std::declval<const SqlRow&>()))>> {
  auto rows = s.Query(sql, params);
  if (!rows.ok()) return rows.status();
  std::vector<decltype(read(std::declval<const SqlRow&>()))> out;
  out.reserve(rows->size());
  for (const auto& r : *rows) out.push_back(read(r));
  return out;
}

// The first row of a query read with `read`, or NotFound(`not_found`).
template <typename Read>
auto One(SqlSource& s, const std::string& sql, const std::vector<SqlValue>& params, const std::string& not_found,
         Read read) -> absl::StatusOr<decltype(read(std::declval<const SqlRow&>()))> {
  auto row = s.QueryOne(sql, params, not_found);
  if (!row.ok()) return row.status();
  return read(*row);
}

int64_t FirstInt(const SqlRow& r) { return r.Int(0); }

}  // namespace

absl::StatusOr<int> SqlStore::SchemaVersion() {
  auto v = Read([](SqlSource& s) { return One(s, "SELECT MAX(version) FROM schema_version", {}, "", FirstInt); });
  if (!v.ok()) return v.status();
  return static_cast<int>(*v);
}

absl::StatusOr<MotorRow> SqlStore::GetMotor(const std::string& serial) {
  return Read([&](SqlSource& s) {
    return One(s, "SELECT serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc FROM motors WHERE serial = ?", {serial},
               absl::StrCat("serial '", serial, "' not found"), [](const SqlRow& r) {
                 return MotorRow{r.Text(0), r.Int32(1), r.Double(2), r.Double(3), r.Text(4)};
               });
  });
}

absl::StatusOr<std::vector<HfPointRow>> SqlStore::LatestRunPoints(const std::string& serial, int64_t* run_id) {
  return Read([&](SqlSource& s) -> absl::StatusOr<std::vector<HfPointRow>> {
    auto q = s.QueryOne("SELECT MAX(run_id) FROM runs WHERE serial = ?", {serial}, "no answer");
    if (!q.ok()) return q.status();
    if (q->IsNull(0)) return absl::NotFoundError(absl::StrCat("serial '", serial, "' has no ingested run"));
    *run_id = q->Int(0);
    return All(s, kPointsOfRun, {*run_id}, ReadPoint);
  });
}

absl::StatusOr<std::vector<HfPointRow>> SqlStore::RunPoints(int64_t run_id) {
  return Read([&](SqlSource& s) { return All(s, kPointsOfRun, {run_id}, ReadPoint); });
}

absl::StatusOr<CalibrationRow> SqlStore::GetCalibration(const std::string& serial, int version) {
  return Read([&](SqlSource& s) {
    if (version > 0) {
      return One(s, absl::StrCat(sql::kCalCols, "WHERE serial = ? AND version = ?"), {serial, int64_t{version}},
                 absl::StrCat("serial '", serial, "' has no calibration version ", version), sql::ReadCal);
    }
    return One(s, absl::StrCat(sql::kCalCols, "WHERE serial = ? ORDER BY version DESC LIMIT 1"), {serial},
               absl::StrCat("serial '", serial, "' has no calibration"), sql::ReadCal);
  });
}

absl::StatusOr<std::vector<CalibrationRow>> SqlStore::LatestCalibrations() {
  return Read([&](SqlSource& s) {
    return All(s,
               absl::StrCat(sql::kCalCols, "c WHERE version = (SELECT MAX(version) FROM calibrations d "
                                           "WHERE d.serial = c.serial) ORDER BY serial", dialect().bytewise),
               {}, sql::ReadCal);
  });
}

absl::StatusOr<std::vector<CalibrationRow>> SqlStore::AllCalibrations() {
  return Read([&](SqlSource& s) {
    return All(s, absl::StrCat(sql::kCalCols, "ORDER BY serial", dialect().bytewise, ", version"), {}, sql::ReadCal);
  });
}

absl::StatusOr<std::vector<MotorSummaryRow>> SqlStore::ListMotors(const std::string& prefix, bool only_failed,
                                                                  int offset, int limit) {
  const std::string sql = absl::StrCat(
      "SELECT m.serial, COALESCE(c.version, 0), COALESCE(c.verdict, ''), "
      "(SELECT COUNT(*) FROM runs r WHERE r.serial = m.serial), "
      "COALESCE(c.created_utc, m.created_utc) FROM motors m "
      "LEFT JOIN calibrations c ON c.serial = m.serial AND c.version = "
      "(SELECT MAX(version) FROM calibrations d WHERE d.serial = m.serial) "
      "WHERE substr(m.serial, 1, length(?)) = ? AND (? = 0 OR c.verdict LIKE 'fail%') "
      "ORDER BY m.serial", dialect().bytewise, " LIMIT ? OFFSET ?");
  return Read([&](SqlSource& s) {
    return All(s, sql, {prefix, prefix, int64_t{only_failed ? 1 : 0}, int64_t{limit}, int64_t{offset}},
               [](const SqlRow& r) {
                 return MotorSummaryRow{r.Text(0), r.Text(2), r.Text(4), r.Int32(1), r.Int32(3)};
               });
  });
}

absl::StatusOr<std::vector<HistoryRow>> SqlStore::History(const std::string& serial) {
  if (auto m = GetMotor(serial); !m.ok()) return m.status();
  return Read([&](SqlSource& s) {
    return All(s,
               "SELECT created_utc, kind, run_id, 0, COALESCE(recording_sha256, '') FROM runs WHERE serial = ? "
               "UNION ALL SELECT created_utc, 'calibration', COALESCE(run_id, 0), version, model || ' ' || verdict "
               "FROM calibrations WHERE serial = ? ORDER BY 1, 3, 4",
               {serial, serial},
               [](const SqlRow& r) { return HistoryRow{r.Text(0), r.Text(1), r.Text(4), r.Int(2), r.Int32(3)}; });
  });
}

absl::StatusOr<RecordingRow> SqlStore::GetRecordingRow(const std::string& sha) {
  return Read([&](SqlSource& s) {
    return One(s, "SELECT size_bytes, zlib_data FROM recordings WHERE sha256 = ?", {sha},
               absl::StrCat("recording ", sha, " not found"),
               [&](const SqlRow& r) { return RecordingRow{sha, r.Int(0), r.Blob(1)}; });
  });
}

absl::StatusOr<std::vector<uint8_t>> SqlStore::GetRecording(const std::string& sha) {
  auto r = GetRecordingRow(sha);
  if (!r.ok()) return r.status();
  return std::move(r->zlib_data);
}

absl::StatusOr<std::string> SqlStore::LatestRecordingSha(const std::string& serial) {
  return Read([&](SqlSource& s) {
    return One(s,
               "SELECT recording_sha256 FROM runs WHERE serial = ? AND recording_sha256 IS NOT NULL "
               "ORDER BY run_id DESC LIMIT 1",
               {serial}, absl::StrCat("serial '", serial, "' has no stored raw recording"),
               [](const SqlRow& r) { return r.Text(0); });
  });
}

absl::StatusOr<int> SqlStore::LatestReleasedVersion(const std::string& serial) {
  auto v = Read([&](SqlSource& s) {
    return One(s, "SELECT COALESCE(MAX(version), 0) FROM releases WHERE serial = ?", {serial}, "", FirstInt);
  });
  if (!v.ok()) return v.status();
  return static_cast<int>(*v);
}

absl::StatusOr<bool> SqlStore::IsReleased(const std::string& serial, int version) {
  auto n = Read([&](SqlSource& s) {
    return One(s, "SELECT COUNT(*) FROM releases WHERE serial = ? AND version = ?", {serial, int64_t{version}}, "",
               FirstInt);
  });
  if (!n.ok()) return n.status();
  return *n > 0;
}

absl::StatusOr<ReleaseRow> SqlStore::GetRelease(const std::string& serial, int version) {
  return Read([&](SqlSource& s) {
    return One(s, absl::StrCat(kReleaseCols, "WHERE serial = ? AND version = ?"), {serial, int64_t{version}},
               absl::StrCat("version ", version, " of '", serial, "' is not released"), ReadRelease);
  });
}

absl::StatusOr<std::vector<ReleaseRow>> SqlStore::AllReleases() {
  return Read([&](SqlSource& s) {
    return All(s, absl::StrCat(kReleaseCols, "ORDER BY serial", dialect().bytewise, ", version"), {}, ReadRelease);
  });
}

absl::StatusOr<std::vector<ReleaseLinkRow>> SqlStore::AllReleaseLinks() {
  return Read([&](SqlSource& s) { return All(s, absl::StrCat(kReleaseLinkCols, "ORDER BY seq"), {}, ReadReleaseLink); });
}

absl::StatusOr<ReleaseLinkRow> SqlStore::ReleaseLink(const std::string& serial, int version) {
  return Read([&](SqlSource& s) {
    return One(s, absl::StrCat(kReleaseLinkCols, "WHERE serial = ? AND version = ?"), {serial, int64_t{version}},
               absl::StrCat(serial, " v", version, ": no release chain link"), ReadReleaseLink);
  });
}

absl::StatusOr<ReleaseLinkRow> SqlStore::ReleaseLinkAt(int64_t seq) {
  const std::string not_found = absl::StrCat("release chain: no link #", seq);
  return Read([&](SqlSource& s) {
    if (seq > 0) return One(s, absl::StrCat(kReleaseLinkCols, "WHERE seq = ?"), {seq}, not_found, ReadReleaseLink);
    return One(s, absl::StrCat(kReleaseLinkCols, "ORDER BY seq DESC LIMIT 1"), {}, not_found, ReadReleaseLink);
  });
}

absl::StatusOr<std::vector<AuditRow>> SqlStore::AuditOf(const std::string& serial) {
  return Read([&](SqlSource& s) { return All(s, absl::StrCat(kAuditCols, "WHERE serial = ? ORDER BY id"), {serial}, ReadAudit); });
}

absl::StatusOr<std::vector<AuditRow>> SqlStore::AllAudit() {
  return Read([&](SqlSource& s) { return All(s, absl::StrCat(kAuditCols, "ORDER BY id"), {}, ReadAudit); });
}

absl::StatusOr<std::vector<ChainRow>> SqlStore::AllChainRows() {
  return Read([&](SqlSource& s) {
    return All(s, absl::StrCat(sql::kChainCols, "ORDER BY serial", dialect().bytewise, ", version"), {},
               sql::ReadChain);
  });
}

absl::StatusOr<ChainRow> SqlStore::ChainLink(const std::string& serial, int version) {
  const std::string not_found = absl::StrCat("serial '", serial, "': no chain link");
  return Read([&](SqlSource& s) {
    if (version > 0) {
      return One(s, absl::StrCat(sql::kChainCols, "WHERE serial = ? AND version = ?"), {serial, int64_t{version}},
                 not_found, sql::ReadChain);
    }
    return One(s, absl::StrCat(sql::kChainCols, "WHERE serial = ? ORDER BY version DESC LIMIT 1"), {serial},
               not_found, sql::ReadChain);
  });
}

absl::StatusOr<std::vector<ConversionRow>> SqlStore::AllConversions() {
  return Read([&](SqlSource& s) {
    return All(s, absl::StrCat(kConversionCols, "ORDER BY serial", dialect().bytewise, ", version"), {},
               ReadConversion);
  });
}

absl::StatusOr<std::optional<ConversionRow>> SqlStore::Conversion(const std::string& serial, int version) {
  auto v = Read([&](SqlSource& s) {
    return All(s, absl::StrCat(kConversionCols, "WHERE serial = ? AND version = ?"), {serial, int64_t{version}},
               ReadConversion);
  });
  if (!v.ok()) return v.status();
  if (v->empty()) return std::optional<ConversionRow>();
  return std::optional<ConversionRow>(v->front());
}

absl::StatusOr<std::vector<MotorRow>> SqlStore::AllMotors() {
  return Read([&](SqlSource& s) {
    return All(s,
               absl::StrCat("SELECT serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc FROM motors ORDER BY serial",
                            dialect().bytewise),
               {}, [](const SqlRow& r) { return MotorRow{r.Text(0), r.Int32(1), r.Double(2), r.Double(3), r.Text(4)}; });
  });
}

absl::StatusOr<std::vector<RunRow>> SqlStore::AllRuns() {
  return Read([&](SqlSource& s) {
    return All(s,
               "SELECT run_id, serial, station, kind, COALESCE(recording_sha256, ''), created_utc, "
               "COALESCE(idempotency_key, '') FROM runs ORDER BY run_id",
               {}, [](const SqlRow& r) {
                 return RunRow{r.Int(0), r.Text(1), r.Text(2), r.Text(3), r.Text(4), r.Text(5), r.Text(6)};
               });
  });
}

// --- Imports: rows copied with their ids, each call one transaction.

absl::Status SqlStore::ImportMotor(const MotorRow& m) {
  return Write([&](SqlSource& s) {
    return s.Exec("INSERT INTO motors (serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc) VALUES (?,?,?,?,?)",
                  {m.serial, int64_t{m.pole_pairs}, m.rs_ohm, m.psi_pm_wb, m.created_utc});
  });
}

absl::Status SqlStore::ImportRun(const RunRow& run, const std::vector<HfPointRow>& points, const RecordingRow* rec) {
  return Write([&](SqlSource& s) -> absl::Status {
    if (rec) {
      if (auto e = s.Exec(sql::kInsertRecording, {rec->sha256, rec->size_bytes, rec->zlib_data}); !e.ok()) return e;
    }
    if (auto e = s.Exec("INSERT INTO runs (run_id, serial, station, kind, recording_sha256, created_utc, "
                        "idempotency_key) VALUES (?,?,?,?,?,?,?)",
                        {run.run_id, run.serial, run.station, run.kind, TextOrNull(run.recording_sha256),
                         run.created_utc, TextOrNull(run.idempotency_key)});
        !e.ok()) {
      return e;
    }
    if (auto e = sql::InsertPoints(s, run.run_id, points); !e.ok()) return e;
    // Later runs continue after the imported ids.
    if (dialect().after_import_runs.empty()) return absl::OkStatus();
    return s.Exec(dialect().after_import_runs);
  });
}

absl::Status SqlStore::ImportCalibration(const CalibrationRow& c) {
  return Write([&](SqlSource& s) { return s.Exec(sql::kInsertCalibration, sql::CalibrationValues(c)); });
}

absl::Status SqlStore::ImportConversions(const std::vector<ConversionRow>& conversions) {
  return Write([&](SqlSource& s) -> absl::Status {
    for (const auto& x : conversions) {
      if (auto e = s.Exec(sql::kInsertConversion, {x.serial, int64_t{x.version}, x.json_sha256, x.row_sha256,
                                                   x.converted_utc});
          !e.ok()) {
        return e;
      }
    }
    return absl::OkStatus();
  });
}

absl::Status SqlStore::ImportTrail(const std::vector<ReleaseRow>& releases, const std::vector<AuditRow>& audit,
                                   const std::vector<ChainRow>& chain,
                                   const std::vector<ReleaseLinkRow>& release_chain) {
  std::vector<std::vector<SqlValue>> rel, au, ch, rc;
  for (const auto& r : releases) rel.push_back({r.serial, int64_t{r.version}, r.released_by, r.released_utc});
  for (const auto& a : audit) {
    au.push_back({a.id, a.utc, a.identity, a.role, a.peer, a.request_id, a.rpc, a.serial, a.detail});
  }
  for (const auto& l : chain) ch.push_back({l.serial, int64_t{l.version}, l.prev_sha256, l.row_sha256});
  for (const auto& l : release_chain) {
    rc.push_back({l.seq, l.serial, int64_t{l.version}, l.calibration_sha256, l.prev_sha256, l.row_sha256});
  }
  return Write([&](SqlSource& s) -> absl::Status {
    if (auto e = s.InsertRows("releases", {"serial", "version", "released_by", "released_utc"}, rel); !e.ok()) return e;
    if (auto e = s.InsertRows(
            "audit", {"id", "utc", "identity", "role", "peer", "request_id", "rpc", "serial", "detail"}, au);
        !e.ok()) {
      return e;
    }
    // Later audit rows continue after the imported ids.
    if (!audit.empty() && !dialect().after_import_audit.empty()) {
      if (auto e = s.Exec(dialect().after_import_audit); !e.ok()) return e;
    }
    if (auto e = s.InsertRows("calibration_chain", {"serial", "version", "prev_sha256", "row_sha256"}, ch); !e.ok()) {
      return e;
    }
    return s.InsertRows("release_chain",
                        {"seq", "serial", "version", "calibration_sha256", "prev_sha256", "row_sha256"}, rc);
  });
}

}  // namespace fluxcal::storage
