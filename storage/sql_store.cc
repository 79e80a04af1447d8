// SqlStore, part 1: opening and migrating a store, and every write.
// Written once for every backend; what differs is in storage/dialect.h.
#include "storage/sql_store.h"

#include "absl/strings/str_cat.h"

namespace fluxcal::storage {
namespace {

// The migration after which releases are chained.
constexpr int kReleaseChainVersion = 7;
// The migration that converts stored JSON to the binary model.
constexpr int kBinaryModelVersion = 8;

// Any constants: the advisory locks (where the dialect has them) that
// serialise migrations, and appends to the one release chain, across servers.
constexpr int64_t kMigrationLock = 0x666c7578;
constexpr int64_t kReleaseChainLock = 0x666c7572;

absl::Status Lock(SqlSource& s, int64_t key) {
  if (s.dialect().advisory_lock.empty()) return absl::OkStatus();
  return s.Exec(s.dialect().advisory_lock, {key});
}

}  // namespace

namespace sql {

CalibrationRow ReadCal(const SqlRow& r) {
  CalibrationRow c;
  c.serial = r.Text(0); c.version = r.Int32(1); c.run_id = r.Int(2);
  c.created_utc = r.Text(3); c.model = r.Text(4); c.psi_pm_wb = r.Double(5);
  c.rms_relative = r.Double(6); c.verdict = r.Text(7); c.calibration_json = r.Text(8);
  c.model_pb = r.Text(9);   // NULL: "" (a version stored as JSON)
  return c;
}

ChainRow ReadChain(const SqlRow& r) { return {r.Text(0), r.Int32(1), r.Text(2), r.Text(3)}; }

std::vector<SqlValue> CalibrationValues(const CalibrationRow& c) {
  return {c.serial, int64_t{c.version}, c.run_id ? SqlValue(c.run_id) : SqlValue(nullptr), c.created_utc, c.model,
          c.psi_pm_wb, c.rms_relative, c.verdict, c.calibration_json, BytesOrNull(c.model_pb)};
}

absl::Status InsertPoints(SqlSource& s, int64_t run_id, const std::vector<HfPointRow>& points) {
  static const std::vector<std::string> kColumns = {"run_id", "idx", "point_id", "id_a", "iq_a", "speed_rpm",
                                                    "ld_h", "lq_h", "ldq_h", "ld_h_std", "lq_h_std", "ldq_h_std",
                                                    "temperature_c", "reliable", "hf_flux_radius_wb"};
  std::vector<std::vector<SqlValue>> rows;
  rows.reserve(points.size());
  for (size_t k = 0; k < points.size(); ++k) {
    const auto& p = points[k];
    rows.push_back({run_id, static_cast<int64_t>(k), p.point_id, p.id_a, p.iq_a, p.speed_rpm, p.ld_h, p.lq_h,
                    p.ldq_h ? SqlValue(*p.ldq_h) : SqlValue(nullptr), p.ld_h_std, p.lq_h_std, p.ldq_h_std,
                    p.temperature_c, int64_t{p.reliable ? 1 : 0},
                    p.hf_flux_radius_wb ? SqlValue(*p.hf_flux_radius_wb) : SqlValue(nullptr)});
  }
  return s.InsertRows("hf_points", kColumns, rows);
}

}  // namespace sql

absl::StatusOr<std::unique_ptr<SqlStore>> SqlStore::Open(std::unique_ptr<SqlPool> pool, bool create,
                                                         JsonToModelFn json_to_model) {
  std::unique_ptr<SqlStore> s(new SqlStore(std::move(pool)));
  if (auto st = s->Migrate(create, json_to_model); !st.ok()) return st;
  return s;
}

absl::Status SqlStore::Write(const std::function<absl::Status(SqlSource&)>& fn) {
  return pool_->WithSource([&](SqlSource& s) -> absl::Status {
    if (auto st = s.Begin(); !st.ok()) return st;
    absl::Status st = fn(s);
    if (st.ok()) {
      st = s.Commit();
      if (st.ok()) return st;
    }
    (void)s.Rollback();
    return st;
  });
}

absl::Status SqlStore::Migrate(bool create, const JsonToModelFn& json_to_model) {
  return Write([&](SqlSource& s) -> absl::Status {
    if (auto st = Lock(s, kMigrationLock); !st.ok()) return st;
    if (!create) {
      // A database without fluxcal's tables is refused, not turned into a store.
      auto q = s.QueryOne(dialect().table_exists, {std::string("schema_version")}, "no answer");
      if (!q.ok()) return q.status();
      if (q->Int(0) == 0) {
        return absl::NotFoundError(
            absl::StrCat(dialect().name, ": the database holds no fluxcal store (no schema_version table)"));
      }
    }
    if (auto st = s.ExecScript("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)"); !st.ok()) {
      return st;
    }
    auto q = s.QueryOne("SELECT COALESCE(MAX(version), 0) FROM schema_version", {}, "no answer");
    if (!q.ok()) return q.status();
    int v = q->Int32(0);
    if (v > kSchemaVersion) {
      return absl::FailedPreconditionError(absl::StrCat("database schema version ", v,
                                                        " is newer than this fluxcal (", kSchemaVersion, ")"));
    }
    for (; v < kSchemaVersion; ++v) {
      if (auto st = s.ExecScript(dialect().migrations[v]); !st.ok()) return st;
      if (v + 1 == kReleaseChainVersion) {
        if (auto st = LinkStoredReleases(s); !st.ok()) return st;
      }
      if (v + 1 == kBinaryModelVersion) {
        if (auto st = ConvertStoredJsonIn(s, json_to_model); !st.ok()) return st;
      }
      if (auto st = s.Exec("INSERT INTO schema_version (version) VALUES (?)", {int64_t{v + 1}}); !st.ok()) return st;
    }
    return absl::OkStatus();
  });
}

absl::Status SqlStore::LinkStoredReleases(SqlSource& s) {
  // Releases stored before the chain join it now, oldest first.
  auto rows = s.Query(absl::StrCat("SELECT serial, version, released_by, released_utc FROM releases "
                                   "ORDER BY released_utc, serial",
                                   dialect().bytewise, ", version"));
  if (!rows.ok()) return rows.status();
  for (const auto& r : *rows) {
    if (auto st = AppendReleaseLink(s, {r.Text(0), r.Int32(1), r.Text(2), r.Text(3)}); !st.ok()) return st;
  }
  return absl::OkStatus();
}

absl::Status SqlStore::ConvertStoredJsonIn(SqlSource& s, const JsonToModelFn& json_to_model) {
  // Inside the migration's transaction. The keys first (rows are read and
  // converted one at a time: a fleet's JSON need not fit in memory).
  auto keys = s.Query(absl::StrCat("SELECT serial, version FROM calibrations ORDER BY serial", dialect().bytewise,
                                   ", version"));
  if (!keys.ok()) return keys.status();
  if (keys->empty() || !json_to_model) return absl::OkStatus();
  // Versions are immutable; the migration is the one sanctioned rewrite,
  // in the same transaction as the trigger's lifting and return.
  if (auto st = s.ExecScript(dialect().unlock_calibrations); !st.ok()) return st;
  const std::string now = NowUtc();
  int converted = 0;
  std::string digest;
  for (const auto& key : *keys) {
    const std::vector<SqlValue> id = {key.Text(0), key.Int(1)};
    auto row = s.QueryOne(absl::StrCat(sql::kCalCols, "WHERE serial = ? AND version = ?"), id, "gone");
    if (!row.ok()) return row.status();
    auto links = s.Query(absl::StrCat(sql::kChainCols, "WHERE serial = ? AND version = ?"), id);
    if (!links.ok()) return links.status();
    std::optional<ChainRow> link;
    if (!links->empty()) link = sql::ReadChain(links->front());
    auto conv = ConvertStoredJson(sql::ReadCal(*row), link ? &*link : nullptr, json_to_model, now);
    if (!conv) continue;
    if (auto st = s.Exec("UPDATE calibrations SET calibration_json = '', model_pb = ? WHERE serial = ? AND version = ?",
                         {BytesOrNull(conv->row.model_pb), id[0], id[1]});
        !st.ok()) {
      return st;
    }
    const ConversionRow& x = conv->record;
    if (auto st = s.Exec(sql::kInsertConversion,
                         {x.serial, int64_t{x.version}, x.json_sha256, x.row_sha256, x.converted_utc});
        !st.ok()) {
      return st;
    }
    absl::StrAppend(&digest, x.serial, "\t", x.version, "\t", x.json_sha256, "\t", x.row_sha256, "\n");
    ++converted;
  }
  if (auto st = s.ExecScript(dialect().relock_calibrations); !st.ok()) return st;
  // The audit trail says what the migration did, with a digest of its records.
  AuditContext audit;
  audit.row = {0, "", "fluxcal", "admin", "", "", "migrate", "",
               ConversionAuditDetail(converted, static_cast<int>(keys->size()), digest)};
  return InsertAudit(s, &audit, 0, false);
}

absl::Status SqlStore::InsertAudit(SqlSource& s, const AuditContext* audit, int64_t written_id, bool replayed) {
  if (audit == nullptr) return absl::OkStatus();
  const AuditRow& a = audit->row;
  const std::string detail = audit->detail ? audit->detail(written_id, replayed) : a.detail;
  return s.Exec(sql::kInsertAudit, {NowUtc(), a.identity, a.role, a.peer, a.request_id, a.rpc, a.serial, detail});
}

absl::Status SqlStore::AppendAudit(const AuditRow& a) {
  return Write([&](SqlSource& s) {
    return s.Exec(sql::kInsertAudit, {NowUtc(), a.identity, a.role, a.peer, a.request_id, a.rpc, a.serial, a.detail});
  });
}

absl::StatusOr<int64_t> SqlStore::IngestHfRun(const MotorRow& m, const std::string& station, const std::string& kind,
                                              const std::vector<HfPointRow>& points, const std::string& sha,
                                              const std::vector<uint8_t>& blob, int64_t recording_bytes,
                                              const std::string& key, bool* replayed, const AuditContext* audit) {
  int64_t run_id = 0;
  if (replayed != nullptr) *replayed = false;
  auto st = Write([&](SqlSource& s) -> absl::Status {
    if (replayed != nullptr) *replayed = false;
    // The upsert first: on PostgreSQL it holds the motor row's lock until
    // commit, so ingests of one serial are serialised and a retry sees the
    // first run (SQLite's write lock does the same).
    if (auto e = s.Exec("INSERT INTO motors (serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc) VALUES (?,?,?,?,?) "
                        "ON CONFLICT (serial) DO UPDATE SET pole_pairs = excluded.pole_pairs, "
                        "rs_ohm = excluded.rs_ohm, psi_pm_wb = excluded.psi_pm_wb",
                        {m.serial, int64_t{m.pole_pairs}, m.rs_ohm, m.psi_pm_wb, NowUtc()});
        !e.ok()) {
      return e;
    }
    if (!key.empty()) {
      auto q = s.Query("SELECT run_id FROM runs WHERE serial = ? AND idempotency_key = ?", {m.serial, key});
      if (!q.ok()) return q.status();
      if (!q->empty()) {
        run_id = q->front().Int(0);
        if (replayed != nullptr) *replayed = true;
        return InsertAudit(s, audit, run_id, true);
      }
    }
    if (!sha.empty()) {
      if (auto e = s.Exec(sql::kInsertRecording, {sha, recording_bytes, blob}); !e.ok()) return e;
    }
    auto run = s.QueryOne(
        "INSERT INTO runs (serial, station, kind, recording_sha256, created_utc, idempotency_key) "
        "VALUES (?,?,?,?,?,?) RETURNING run_id",
        {m.serial, station, kind, TextOrNull(sha), NowUtc(), TextOrNull(key)}, "INSERT INTO runs returned no id");
    if (!run.ok()) return run.status();
    run_id = run->Int(0);
    if (auto e = sql::InsertPoints(s, run_id, points); !e.ok()) return e;
    return InsertAudit(s, audit, run_id, false);
  });
  if (!st.ok()) return st;
  return run_id;
}

absl::StatusOr<int> SqlStore::AddCalibration(const CalibrationRow& c, const AuditContext* audit) {
  int version = 0;
  auto st = Write([&](SqlSource& s) -> absl::Status {
    // The motor row lock (PostgreSQL; SQLite holds the file's write lock)
    // serialises version assignment for this serial across processes.
    auto motor = s.QueryOne(absl::StrCat("SELECT 1 FROM motors WHERE serial = ?", dialect().for_update), {c.serial},
                            absl::StrCat("serial '", c.serial, "' not found"));
    if (!motor.ok()) return motor.status();
    auto q = s.QueryOne("SELECT COALESCE(MAX(version), 0) FROM calibrations WHERE serial = ?", {c.serial}, "no answer");
    if (!q.ok()) return q.status();
    version = q->Int32(0) + 1;
    CalibrationRow row = c;
    row.version = version;
    row.created_utc = NowUtc();
    if (auto e = s.Exec(sql::kInsertCalibration, sql::CalibrationValues(row)); !e.ok()) return e;
    auto prev = s.Query("SELECT row_sha256 FROM calibration_chain WHERE serial = ? ORDER BY version DESC LIMIT 1",
                        {c.serial});
    if (!prev.ok()) return prev.status();
    const std::string prev_sha = prev->empty() ? std::string() : prev->front().Text(0);
    if (auto e = s.Exec("INSERT INTO calibration_chain (serial, version, prev_sha256, row_sha256) VALUES (?,?,?,?)",
                        {c.serial, int64_t{version}, prev_sha, CalibrationRowSha256(prev_sha, row)});
        !e.ok()) {
      return e;
    }
    return InsertAudit(s, audit, version, false);
  });
  if (!st.ok()) return st;
  return version;
}

absl::Status SqlStore::Release(const std::string& serial, int version, const std::string& by,
                               const AuditContext* audit) {
  return Write([&](SqlSource& s) -> absl::Status {
    // One release chain for the store: appends from every server in turn.
    if (auto e = Lock(s, kReleaseChainLock); !e.ok()) return e;
    // FOR SHARE (PostgreSQL): the calibration row cannot change anyway
    // (immutable), but the lock orders concurrent releases of one version.
    auto q = s.QueryOne(absl::StrCat("SELECT verdict FROM calibrations WHERE serial = ? AND version = ?",
                                     dialect().for_share),
                        {serial, int64_t{version}},
                        absl::StrCat("serial '", serial, "' has no calibration version ", version));
    if (!q.ok()) return q.status();
    const std::string verdict = q->Text(0);
    if (verdict != "pass") {
      return absl::FailedPreconditionError(absl::StrCat("version ", version, " of '", serial, "' has verdict '",
                                                        verdict, "'; only 'pass' can be released"));
    }
    const ReleaseRow row{serial, version, by, NowUtc()};
    auto ins = s.Query("INSERT INTO releases (serial, version, released_by, released_utc) VALUES (?,?,?,?) "
                       "ON CONFLICT DO NOTHING RETURNING version",
                       {row.serial, int64_t{row.version}, row.released_by, row.released_utc});
    if (!ins.ok()) return ins.status();
    if (ins->empty()) {
      return absl::AlreadyExistsError(absl::StrCat("version ", version, " of '", serial, "' is released already"));
    }
    if (auto e = AppendReleaseLink(s, row); !e.ok()) return e;
    return InsertAudit(s, audit, version, false);
  });
}

absl::Status SqlStore::AppendReleaseLink(SqlSource& s, const ReleaseRow& r) {
  // The released version's hash: its chain link, or its content for a
  // version from before the chain.
  const std::vector<SqlValue> id = {r.serial, int64_t{r.version}};
  auto link = s.Query("SELECT row_sha256 FROM calibration_chain WHERE serial = ? AND version = ?", id);
  if (!link.ok()) return link.status();
  std::string calibration_sha;
  if (!link->empty()) {
    calibration_sha = link->front().Text(0);
  } else {
    auto row = s.QueryOne(absl::StrCat(sql::kCalCols, "WHERE serial = ? AND version = ?"), id,
                          absl::StrCat("serial '", r.serial, "' has no calibration version ", r.version));
    if (!row.ok()) return row.status();
    calibration_sha = VersionSha256(sql::ReadCal(*row), nullptr);
  }
  // The caller's lock (advisory or the file's) keeps the newest link still.
  auto last = s.Query("SELECT seq, row_sha256 FROM release_chain ORDER BY seq DESC LIMIT 1");
  if (!last.ok()) return last.status();
  const int64_t seq = last->empty() ? 1 : last->front().Int(0) + 1;
  const std::string prev = last->empty() ? std::string() : last->front().Text(1);
  return s.Exec(
      "INSERT INTO release_chain (seq, serial, version, calibration_sha256, prev_sha256, row_sha256) "
      "VALUES (?,?,?,?,?,?)",
      {seq, r.serial, int64_t{r.version}, calibration_sha, prev, ReleaseRowSha256(prev, seq, r, calibration_sha)});
}

}  // namespace fluxcal::storage
