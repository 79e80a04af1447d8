#include "storage/sqlite_store.h"

#include "absl/strings/str_cat.h"

namespace fluxcal::storage {
namespace {

// The migration after which releases are chained.
constexpr int kReleaseChainVersion = 7;
// The migration that converts stored JSON to the binary model.
constexpr int kBinaryModelVersion = 8;

SqlValue BlobOrNull(const std::string& bytes) {
  return bytes.empty() ? SqlValue(nullptr) : SqlValue(std::vector<uint8_t>(bytes.begin(), bytes.end()));
}

}  // namespace

absl::StatusOr<std::unique_ptr<SqliteStore>> SqliteStore::Open(const std::string& path, bool create,
                                                               JsonToModelFn json_to_model) {
  // A read-only caller's path must already be a fluxcal store.
  auto db = Database::Open(path, create, create ? "" : "schema_version");
  if (!db.ok() && !create && db.status().code() == absl::StatusCode::kNotFound &&
      db.status().message().find("has no table") != std::string_view::npos) {
    return absl::NotFoundError(absl::StrCat("sqlite: '", path, "' holds no fluxcal store (no schema_version table)"));
  }
  if (!db.ok()) return db.status();
  std::unique_ptr<SqliteStore> s(new SqliteStore(path, std::move(*db)));
  if (auto st = s->Migrate(json_to_model); !st.ok()) return st;
  return s;
}

absl::Status SqliteStore::Migrate(const JsonToModelFn& json_to_model) {
  std::lock_guard<std::mutex> lock(write_mu_);
  if (auto st = writer_->Exec("CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)"); !st.ok()) return st;
  return writer_->Transaction([&]() -> absl::Status {
    auto q = writer_->Prepare("SELECT COALESCE(MAX(version), 0) FROM schema_version");
    if (!q.ok()) return q.status();
    auto row = q->Step();
    if (!row.ok()) return row.status();
    int v = static_cast<int>(q->Int(0));
    if (v > kSchemaVersion) {
      return absl::FailedPreconditionError(absl::StrCat("database schema version ", v,
                                                        " is newer than this fluxcal (", kSchemaVersion, ")"));
    }
    for (; v < kSchemaVersion; ++v) {
      if (auto st = writer_->Exec(SqliteMigrations()[v]); !st.ok()) return st;
      if (v + 1 == kReleaseChainVersion) {
        // Releases stored before the chain join it now, oldest first.
        auto rel = writer_->Prepare(
            "SELECT serial, version, released_by, released_utc FROM releases ORDER BY released_utc, serial, version");
        if (!rel.ok()) return rel.status();
        std::vector<ReleaseRow> existing;
        while (true) {
          auto r = rel->Step();
          if (!r.ok()) return r.status();
          if (!*r) break;
          existing.push_back({rel->Text(0), static_cast<int>(rel->Int(1)), rel->Text(2), rel->Text(3)});
        }
        for (const auto& r : existing) {
          if (auto st = AppendReleaseLinkLocked(r); !st.ok()) return st;
        }
      }
      if (v + 1 == kBinaryModelVersion) {
        if (auto st = ConvertStoredJsonLocked(json_to_model); !st.ok()) return st;
      }
      auto ins = writer_->Prepare("INSERT INTO schema_version (version) VALUES (?)");
      if (!ins.ok()) return ins.status();
      if (auto st = ins->Bind(1, int64_t{v + 1}); !st.ok()) return st;
      if (auto r = ins->Step(); !r.ok()) return r.status();
    }
    return absl::OkStatus();
  });
}

absl::StatusOr<int> SqliteStore::SchemaVersion() {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare("SELECT MAX(version) FROM schema_version");
  if (!q.ok()) return q.status();
  if (auto r = q->Step(); !r.ok()) return r.status();
  return static_cast<int>(q->Int(0));
}

absl::StatusOr<int64_t> SqliteStore::IngestHfRun(const MotorRow& m, const std::string& station, const std::string& kind,
                                           const std::vector<HfPointRow>& points, const std::string& sha,
                                           const std::vector<uint8_t>& blob, int64_t recording_bytes,
                                           const std::string& key, bool* replayed, const AuditContext* audit) {
  std::lock_guard<std::mutex> lock(write_mu_);
  int64_t run_id = 0;
  if (replayed != nullptr) *replayed = false;
  auto st = writer_->Transaction([&]() -> absl::Status {
    if (!key.empty()) {
      auto q = writer_->Prepare("SELECT run_id FROM runs WHERE serial = ? AND idempotency_key = ?");
      if (!q.ok()) return q.status();
      if (auto s = q->BindAll({m.serial, key}); !s.ok()) return s;
      auto r = q->Step();
      if (!r.ok()) return r.status();
      if (*r) {
        run_id = q->Int(0);
        if (replayed != nullptr) *replayed = true;
        return InsertAuditLocked(audit, run_id, true);
      }
    }
    auto up = writer_->Prepare(
        "INSERT INTO motors (serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc) VALUES (?,?,?,?,?) "
        "ON CONFLICT(serial) DO UPDATE SET pole_pairs = excluded.pole_pairs, rs_ohm = excluded.rs_ohm, "
        "psi_pm_wb = excluded.psi_pm_wb");
    if (!up.ok()) return up.status();
    if (auto s = up->BindAll({m.serial, int64_t{m.pole_pairs}, m.rs_ohm, m.psi_pm_wb, NowUtc()}); !s.ok()) return s;
    if (auto r = up->Step(); !r.ok()) return r.status();
    if (!sha.empty()) {
      auto rec = writer_->Prepare("INSERT OR IGNORE INTO recordings (sha256, size_bytes, zlib_data) VALUES (?,?,?)");
      if (!rec.ok()) return rec.status();
      if (auto s = rec->BindAll({sha, recording_bytes, blob}); !s.ok()) return s;
      if (auto r = rec->Step(); !r.ok()) return r.status();
    }
    auto run = writer_->Prepare(
        "INSERT INTO runs (serial, station, kind, recording_sha256, created_utc, idempotency_key) VALUES (?,?,?,?,?,?)");
    if (!run.ok()) return run.status();
    if (auto s = run->BindAll({m.serial, station, kind, sha.empty() ? SqlValue(nullptr) : SqlValue(sha), NowUtc(),
                               key.empty() ? SqlValue(nullptr) : SqlValue(key)});
        !s.ok()) {
      return s;
    }
    if (auto r = run->Step(); !r.ok()) return r.status();
    run_id = writer_->LastInsertRowId();
    if (auto s = InsertPointsLocked(run_id, points); !s.ok()) return s;
    return InsertAuditLocked(audit, run_id, false);
  });
  if (!st.ok()) return st;
  return run_id;
}

absl::Status SqliteStore::Release(const std::string& serial, int version, const std::string& by,
                                  const AuditContext* audit) {
  std::lock_guard<std::mutex> lock(write_mu_);
  return writer_->Transaction([&]() -> absl::Status {
    auto q = writer_->Prepare("SELECT verdict FROM calibrations WHERE serial = ? AND version = ?");
    if (!q.ok()) return q.status();
    if (auto s = q->BindAll({serial, int64_t{version}}); !s.ok()) return s;
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) return absl::NotFoundError(absl::StrCat("serial '", serial, "' has no calibration version ", version));
    const std::string verdict = q->Text(0);
    if (verdict != "pass") {
      return absl::FailedPreconditionError(
          absl::StrCat("version ", version, " of '", serial, "' has verdict '", verdict, "'; only 'pass' can be released"));
    }
    auto e = writer_->Prepare("SELECT 1 FROM releases WHERE serial = ? AND version = ?");
    if (!e.ok()) return e.status();
    if (auto s = e->BindAll({serial, int64_t{version}}); !s.ok()) return s;
    auto er = e->Step();
    if (!er.ok()) return er.status();
    if (*er) return absl::AlreadyExistsError(absl::StrCat("version ", version, " of '", serial, "' is released already"));
    const ReleaseRow row{serial, version, by, NowUtc()};
    auto ins = writer_->Prepare("INSERT INTO releases (serial, version, released_by, released_utc) VALUES (?,?,?,?)");
    if (!ins.ok()) return ins.status();
    if (auto s = ins->BindAll({row.serial, int64_t{row.version}, row.released_by, row.released_utc}); !s.ok()) return s;
    if (auto ir = ins->Step(); !ir.ok()) return ir.status();
    if (auto s = AppendReleaseLinkLocked(row); !s.ok()) return s;
    return InsertAuditLocked(audit, version, false);
  });
}

absl::Status SqliteStore::AppendReleaseLinkLocked(const ReleaseRow& r) {
  // The released version's hash: its chain link, or its content for a
  // version from before the chain.
  auto l = writer_->Prepare("SELECT row_sha256 FROM calibration_chain WHERE serial = ? AND version = ?");
  if (!l.ok()) return l.status();
  if (auto s = l->BindAll({r.serial, int64_t{r.version}}); !s.ok()) return s;
  auto lr = l->Step();
  if (!lr.ok()) return lr.status();
  std::string calibration_sha;
  if (*lr) {
    calibration_sha = l->Text(0);
  } else {
    auto row = CalibrationLocked(r.serial, r.version);
    if (!row.ok()) return row.status();
    calibration_sha = VersionSha256(*row, nullptr);
  }
  // BEGIN IMMEDIATE holds the file's write lock: the newest link cannot
  // move under us, also across processes.
  auto last = writer_->Prepare("SELECT seq, row_sha256 FROM release_chain ORDER BY seq DESC LIMIT 1");
  if (!last.ok()) return last.status();
  auto lastr = last->Step();
  if (!lastr.ok()) return lastr.status();
  const int64_t seq = *lastr ? last->Int(0) + 1 : 1;
  const std::string prev = *lastr ? last->Text(1) : std::string();
  auto ins = writer_->Prepare(
      "INSERT INTO release_chain (seq, serial, version, calibration_sha256, prev_sha256, row_sha256) "
      "VALUES (?,?,?,?,?,?)");
  if (!ins.ok()) return ins.status();
  if (auto s = ins->BindAll({seq, r.serial, int64_t{r.version}, calibration_sha, prev,
                             ReleaseRowSha256(prev, seq, r, calibration_sha)});
      !s.ok()) {
    return s;
  }
  auto ir = ins->Step();
  return ir.ok() ? absl::OkStatus() : ir.status();
}

absl::StatusOr<ReleaseRow> SqliteStore::GetRelease(const std::string& serial, int version) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(
      "SELECT serial, version, released_by, released_utc FROM releases WHERE serial = ? AND version = ?");
  if (!q.ok()) return q.status();
  if (auto s = q->BindAll({serial, int64_t{version}}); !s.ok()) return s;
  auto r = q->Step();
  if (!r.ok()) return r.status();
  if (!*r) return absl::NotFoundError(absl::StrCat("version ", version, " of '", serial, "' is not released"));
  return ReleaseRow{q->Text(0), static_cast<int>(q->Int(1)), q->Text(2), q->Text(3)};
}

absl::StatusOr<std::vector<ReleaseLinkRow>> SqliteStore::ReleaseLinksLocked(const std::string& where,
                                                                            const std::vector<SqlValue>& args) {
  auto q = writer_->Prepare(absl::StrCat(
      "SELECT seq, serial, version, calibration_sha256, prev_sha256, row_sha256 FROM release_chain ", where));
  if (!q.ok()) return q.status();
  if (auto s = q->BindAll(args); !s.ok()) return s;
  std::vector<ReleaseLinkRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back({q->Int(0), q->Text(1), static_cast<int>(q->Int(2)), q->Text(3), q->Text(4), q->Text(5)});
  }
  return out;
}

absl::StatusOr<std::vector<ReleaseLinkRow>> SqliteStore::AllReleaseLinks() {
  std::lock_guard<std::mutex> lock(write_mu_);
  return ReleaseLinksLocked("ORDER BY seq", {});
}

absl::StatusOr<ReleaseLinkRow> SqliteStore::ReleaseLink(const std::string& serial, int version) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto v = ReleaseLinksLocked("WHERE serial = ? AND version = ?", {serial, int64_t{version}});
  if (!v.ok()) return v.status();
  if (v->empty()) return absl::NotFoundError(absl::StrCat(serial, " v", version, ": no release chain link"));
  return v->front();
}

absl::StatusOr<ReleaseLinkRow> SqliteStore::ReleaseLinkAt(int64_t seq) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto v = seq > 0 ? ReleaseLinksLocked("WHERE seq = ?", {seq}) : ReleaseLinksLocked("ORDER BY seq DESC LIMIT 1", {});
  if (!v.ok()) return v.status();
  if (v->empty()) return absl::NotFoundError(absl::StrCat("release chain: no link #", seq));
  return v->front();
}

absl::StatusOr<int> SqliteStore::LatestReleasedVersion(const std::string& serial) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare("SELECT COALESCE(MAX(version), 0) FROM releases WHERE serial = ?");
  if (!q.ok()) return q.status();
  (void)q->Bind(1, serial);
  auto r = q->Step();
  if (!r.ok()) return r.status();
  return static_cast<int>(q->Int(0));
}

absl::StatusOr<bool> SqliteStore::IsReleased(const std::string& serial, int version) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare("SELECT COUNT(*) FROM releases WHERE serial = ? AND version = ?");
  if (!q.ok()) return q.status();
  if (auto s = q->BindAll({serial, int64_t{version}}); !s.ok()) return s;
  auto r = q->Step();
  if (!r.ok()) return r.status();
  return q->Int(0) > 0;
}

absl::Status SqliteStore::InsertAuditLocked(const AuditContext* audit, int64_t written_id, bool replayed) {
  if (audit == nullptr) return absl::OkStatus();
  const AuditRow& a = audit->row;
  const std::string detail = audit->detail ? audit->detail(written_id, replayed) : a.detail;
  auto q = writer_->Prepare(
      "INSERT INTO audit (utc, identity, role, peer, request_id, rpc, serial, detail) VALUES (?,?,?,?,?,?,?,?)");
  if (!q.ok()) return q.status();
  if (auto s = q->BindAll({NowUtc(), a.identity, a.role, a.peer, a.request_id, a.rpc, a.serial, detail}); !s.ok()) {
    return s;
  }
  auto r = q->Step();
  return r.ok() ? absl::OkStatus() : r.status();
}

absl::Status SqliteStore::AppendAudit(const AuditRow& a) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(
      "INSERT INTO audit (utc, identity, role, peer, request_id, rpc, serial, detail) VALUES (?,?,?,?,?,?,?,?)");
  if (!q.ok()) return q.status();
  if (auto s = q->BindAll({NowUtc(), a.identity, a.role, a.peer, a.request_id, a.rpc, a.serial, a.detail}); !s.ok()) {
    return s;
  }
  auto r = q->Step();
  return r.ok() ? absl::OkStatus() : r.status();
}

absl::StatusOr<std::vector<AuditRow>> SqliteStore::AuditOf(const std::string& serial) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(
      "SELECT id, utc, identity, role, peer, request_id, rpc, serial, detail FROM audit WHERE serial = ? ORDER BY id");
  if (!q.ok()) return q.status();
  (void)q->Bind(1, serial);
  std::vector<AuditRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back({q->Int(0), q->Text(1), q->Text(2), q->Text(3), q->Text(4), q->Text(5), q->Text(6), q->Text(7),
                   q->Text(8)});
  }
  return out;
}

absl::StatusOr<std::vector<ChainRow>> SqliteStore::AllChainRows() {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(
      "SELECT serial, version, prev_sha256, row_sha256 FROM calibration_chain ORDER BY serial, version");
  if (!q.ok()) return q.status();
  std::vector<ChainRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back({q->Text(0), static_cast<int>(q->Int(1)), q->Text(2), q->Text(3)});
  }
  return out;
}

absl::StatusOr<ChainRow> SqliteStore::ChainLink(const std::string& serial, int version) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(absl::StrCat("SELECT serial, version, prev_sha256, row_sha256 FROM calibration_chain ",
                                         version > 0 ? "WHERE serial = ? AND version = ?"
                                                     : "WHERE serial = ? ORDER BY version DESC LIMIT 1"));
  if (!q.ok()) return q.status();
  (void)q->Bind(1, serial);
  if (version > 0) (void)q->Bind(2, int64_t{version});
  auto r = q->Step();
  if (!r.ok()) return r.status();
  if (!*r) return absl::NotFoundError(absl::StrCat("serial '", serial, "': no chain link"));
  return ChainRow{q->Text(0), static_cast<int>(q->Int(1)), q->Text(2), q->Text(3)};
}

absl::StatusOr<MotorRow> SqliteStore::GetMotor(const std::string& serial) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare("SELECT pole_pairs, rs_ohm, psi_pm_wb, created_utc FROM motors WHERE serial = ?");
  if (!q.ok()) return q.status();
  (void)q->Bind(1, serial);
  auto r = q->Step();
  if (!r.ok()) return r.status();
  if (!*r) return absl::NotFoundError(absl::StrCat("serial '", serial, "' not found"));
  return MotorRow{serial, static_cast<int>(q->Int(0)), q->Double(1), q->Double(2), q->Text(3)};
}

absl::StatusOr<std::vector<HfPointRow>> SqliteStore::LatestRunPoints(const std::string& serial, int64_t* run_id) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare("SELECT MAX(run_id) FROM runs WHERE serial = ?");
  if (!q.ok()) return q.status();
  (void)q->Bind(1, serial);
  if (auto r = q->Step(); !r.ok()) return r.status();
  if (q->IsNull(0)) return absl::NotFoundError(absl::StrCat("serial '", serial, "' has no ingested run"));
  *run_id = q->Int(0);
  return PointsLocked(*run_id);
}

absl::StatusOr<int> SqliteStore::AddCalibration(const CalibrationRow& c, const AuditContext* audit) {
  std::lock_guard<std::mutex> lock(write_mu_);
  int version = 0;
  auto st = writer_->Transaction([&]() -> absl::Status {
    auto q = writer_->Prepare("SELECT COALESCE(MAX(version), 0) FROM calibrations WHERE serial = ?");
    if (!q.ok()) return q.status();
    (void)q->Bind(1, c.serial);
    if (auto r = q->Step(); !r.ok()) return r.status();
    version = static_cast<int>(q->Int(0)) + 1;
    CalibrationRow row = c;
    row.version = version;
    row.created_utc = NowUtc();
    auto ins = writer_->Prepare(
        "INSERT INTO calibrations (serial, version, run_id, created_utc, model, psi_pm_wb, rms_relative, verdict, "
        "calibration_json, model_pb) VALUES (?,?,?,?,?,?,?,?,?,?)");
    if (!ins.ok()) return ins.status();
    if (auto s = ins->BindAll({c.serial, int64_t{version}, c.run_id ? SqlValue(c.run_id) : SqlValue(nullptr),
                               row.created_utc, c.model, c.psi_pm_wb, c.rms_relative, c.verdict, c.calibration_json,
                               BlobOrNull(c.model_pb)});
        !s.ok()) {
      return s;
    }
    if (auto r = ins->Step(); !r.ok()) return r.status();
    auto prev = writer_->Prepare("SELECT row_sha256 FROM calibration_chain WHERE serial = ? ORDER BY version DESC LIMIT 1");
    if (!prev.ok()) return prev.status();
    (void)prev->Bind(1, c.serial);
    auto pr = prev->Step();
    if (!pr.ok()) return pr.status();
    const std::string prev_sha = *pr ? prev->Text(0) : std::string();
    auto link = writer_->Prepare(
        "INSERT INTO calibration_chain (serial, version, prev_sha256, row_sha256) VALUES (?,?,?,?)");
    if (!link.ok()) return link.status();
    if (auto s = link->BindAll({c.serial, int64_t{version}, prev_sha, CalibrationRowSha256(prev_sha, row)}); !s.ok()) {
      return s;
    }
    if (auto r = link->Step(); !r.ok()) return r.status();
    return InsertAuditLocked(audit, version, false);
  });
  if (!st.ok()) return st;
  return version;
}

namespace {
CalibrationRow ReadCal(const Statement& q) {
  CalibrationRow c;
  c.serial = q.Text(0); c.version = static_cast<int>(q.Int(1)); c.run_id = q.Int(2);
  c.created_utc = q.Text(3); c.model = q.Text(4); c.psi_pm_wb = q.Double(5);
  c.rms_relative = q.Double(6); c.verdict = q.Text(7); c.calibration_json = q.Text(8);
  if (!q.IsNull(9)) {
    const auto b = q.Blob(9);
    c.model_pb.assign(b.begin(), b.end());
  }
  return c;
}
constexpr char kCalCols[] =
    "SELECT serial, version, COALESCE(run_id, 0), created_utc, model, psi_pm_wb, rms_relative, verdict, "
    "calibration_json, model_pb FROM calibrations ";
}  // namespace

absl::StatusOr<CalibrationRow> SqliteStore::CalibrationLocked(const std::string& serial, int version) {
  auto c = writer_->Prepare(absl::StrCat(kCalCols, "WHERE serial = ? AND version = ?"));
  if (!c.ok()) return c.status();
  if (auto s = c->BindAll({serial, int64_t{version}}); !s.ok()) return s;
  auto cr = c->Step();
  if (!cr.ok()) return cr.status();
  if (!*cr) return absl::NotFoundError(absl::StrCat("serial '", serial, "' has no calibration version ", version));
  return ReadCal(*c);
}

absl::Status SqliteStore::ConvertStoredJsonLocked(const JsonToModelFn& json_to_model) {
  // Inside the migration's transaction. The keys first (rows are read and
  // converted one at a time: a fleet's JSON need not fit in memory).
  std::vector<std::pair<std::string, int64_t>> keys;
  {
    auto q = writer_->Prepare("SELECT serial, version FROM calibrations ORDER BY serial, version");
    if (!q.ok()) return q.status();
    while (true) {
      auto r = q->Step();
      if (!r.ok()) return r.status();
      if (!*r) break;
      keys.push_back({q->Text(0), q->Int(1)});
    }
  }
  if (keys.empty() || !json_to_model) return absl::OkStatus();
  // Versions are immutable; the migration is the one sanctioned rewrite,
  // in the same transaction as the trigger's removal and return.
  if (auto st = writer_->Exec("DROP TRIGGER calibrations_no_update"); !st.ok()) return st;
  const std::string now = NowUtc();
  int converted = 0;
  std::string digest;
  for (const auto& [serial, version] : keys) {
    auto row = CalibrationLocked(serial, static_cast<int>(version));
    if (!row.ok()) return row.status();
    std::optional<ChainRow> link;
    {
      auto l = writer_->Prepare(
          "SELECT serial, version, prev_sha256, row_sha256 FROM calibration_chain WHERE serial = ? AND version = ?");
      if (!l.ok()) return l.status();
      if (auto s = l->BindAll({serial, version}); !s.ok()) return s;
      auto lr = l->Step();
      if (!lr.ok()) return lr.status();
      if (*lr) link = ChainRow{l->Text(0), static_cast<int>(l->Int(1)), l->Text(2), l->Text(3)};
    }
    auto conv = ConvertStoredJson(*row, link ? &*link : nullptr, json_to_model, now);
    if (!conv) continue;
    auto up = writer_->Prepare(
        "UPDATE calibrations SET calibration_json = '', model_pb = ? WHERE serial = ? AND version = ?");
    if (!up.ok()) return up.status();
    if (auto s = up->BindAll({BlobOrNull(conv->row.model_pb), serial, version}); !s.ok()) return s;
    if (auto r = up->Step(); !r.ok()) return r.status();
    const ConversionRow& x = conv->record;
    auto ins = writer_->Prepare(
        "INSERT INTO calibration_conversions (serial, version, json_sha256, row_sha256, converted_utc) "
        "VALUES (?,?,?,?,?)");
    if (!ins.ok()) return ins.status();
    if (auto s = ins->BindAll({x.serial, int64_t{x.version}, x.json_sha256, x.row_sha256, x.converted_utc}); !s.ok()) {
      return s;
    }
    if (auto r = ins->Step(); !r.ok()) return r.status();
    absl::StrAppend(&digest, x.serial, "\t", x.version, "\t", x.json_sha256, "\t", x.row_sha256, "\n");
    ++converted;
  }
  if (auto st = writer_->Exec(
          "CREATE TRIGGER calibrations_no_update BEFORE UPDATE ON calibrations "
          "BEGIN SELECT RAISE(ABORT, 'calibration versions are immutable'); END;");
      !st.ok()) {
    return st;
  }
  // The audit trail says what the migration did, with a digest of its records.
  AuditContext audit;
  audit.row = {0, "", "fluxcal", "admin", "", "", "migrate", "",
               ConversionAuditDetail(converted, static_cast<int>(keys.size()), digest)};
  return InsertAuditLocked(&audit, 0, false);
}

absl::StatusOr<std::vector<ConversionRow>> SqliteStore::ConversionsLocked(const std::string& where,
                                                                         const std::vector<SqlValue>& args) {
  auto q = writer_->Prepare(absl::StrCat(
      "SELECT serial, version, json_sha256, row_sha256, converted_utc FROM calibration_conversions ", where));
  if (!q.ok()) return q.status();
  if (auto s = q->BindAll(args); !s.ok()) return s;
  std::vector<ConversionRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back({q->Text(0), static_cast<int>(q->Int(1)), q->Text(2), q->Text(3), q->Text(4)});
  }
  return out;
}

absl::StatusOr<std::vector<ConversionRow>> SqliteStore::AllConversions() {
  std::lock_guard<std::mutex> lock(write_mu_);
  return ConversionsLocked("ORDER BY serial, version", {});
}

absl::StatusOr<std::optional<ConversionRow>> SqliteStore::Conversion(const std::string& serial, int version) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto v = ConversionsLocked("WHERE serial = ? AND version = ?", {serial, int64_t{version}});
  if (!v.ok()) return v.status();
  if (v->empty()) return std::optional<ConversionRow>();
  return std::optional<ConversionRow>(v->front());
}

absl::Status SqliteStore::ImportConversions(const std::vector<ConversionRow>& conversions) {
  std::lock_guard<std::mutex> lock(write_mu_);
  return writer_->Transaction([&]() -> absl::Status {
    auto ins = writer_->Prepare(
        "INSERT INTO calibration_conversions (serial, version, json_sha256, row_sha256, converted_utc) "
        "VALUES (?,?,?,?,?)");
    if (!ins.ok()) return ins.status();
    for (const auto& x : conversions) {
      if (auto s = ins->BindAll({x.serial, int64_t{x.version}, x.json_sha256, x.row_sha256, x.converted_utc});
          !s.ok()) {
        return s;
      }
      if (auto r = ins->Step(); !r.ok()) return r.status();
      (void)ins->Reset();
    }
    return absl::OkStatus();
  });
}

absl::StatusOr<CalibrationRow> SqliteStore::GetCalibration(const std::string& serial, int version) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(absl::StrCat(kCalCols, version > 0 ? "WHERE serial = ? AND version = ?"
                                                               : "WHERE serial = ? ORDER BY version DESC LIMIT 1"));
  if (!q.ok()) return q.status();
  (void)q->Bind(1, serial);
  if (version > 0) (void)q->Bind(2, int64_t{version});
  auto r = q->Step();
  if (!r.ok()) return r.status();
  if (!*r) {
    return absl::NotFoundError(version > 0 ? absl::StrCat("serial '", serial, "' has no calibration version ", version)
                                           : absl::StrCat("serial '", serial, "' has no calibration"));
  }
  return ReadCal(*q);
}

absl::StatusOr<std::vector<CalibrationRow>> SqliteStore::LatestCalibrations() {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(absl::StrCat(
      kCalCols, "c WHERE version = (SELECT MAX(version) FROM calibrations d WHERE d.serial = c.serial) ORDER BY serial"));
  if (!q.ok()) return q.status();
  std::vector<CalibrationRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back(ReadCal(*q));
  }
  return out;
}

absl::StatusOr<std::vector<MotorSummaryRow>> SqliteStore::ListMotors(const std::string& prefix, bool only_failed,
                                                               int offset, int limit) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(
      "SELECT m.serial, COALESCE(c.version, 0), COALESCE(c.verdict, ''), "
      "(SELECT COUNT(*) FROM runs r WHERE r.serial = m.serial), "
      "COALESCE(c.created_utc, m.created_utc) FROM motors m "
      "LEFT JOIN calibrations c ON c.serial = m.serial AND c.version = "
      "(SELECT MAX(version) FROM calibrations d WHERE d.serial = m.serial) "
      "WHERE substr(m.serial, 1, length(?1)) = ?1 AND (?2 = 0 OR c.verdict LIKE 'fail%') "
      "ORDER BY m.serial LIMIT ?3 OFFSET ?4");
  if (!q.ok()) return q.status();
  if (auto s = q->BindAll({prefix, int64_t{only_failed ? 1 : 0}, int64_t{limit}, int64_t{offset}}); !s.ok()) return s;
  std::vector<MotorSummaryRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back({q->Text(0), q->Text(2), q->Text(4), static_cast<int>(q->Int(1)), static_cast<int>(q->Int(3))});
  }
  return out;
}

absl::StatusOr<std::vector<HistoryRow>> SqliteStore::History(const std::string& serial) {
  if (auto m = GetMotor(serial); !m.ok()) return m.status();
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(
      "SELECT created_utc, kind, run_id, 0, COALESCE(recording_sha256, '') FROM runs WHERE serial = ?1 "
      "UNION ALL SELECT created_utc, 'calibration', COALESCE(run_id, 0), version, model || ' ' || verdict "
      "FROM calibrations WHERE serial = ?1 ORDER BY 1, 3, 4");
  if (!q.ok()) return q.status();
  (void)q->Bind(1, serial);
  std::vector<HistoryRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back({q->Text(0), q->Text(1), q->Text(4), q->Int(2), static_cast<int>(q->Int(3))});
  }
  return out;
}

absl::StatusOr<std::vector<uint8_t>> SqliteStore::GetRecording(const std::string& sha) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare("SELECT zlib_data FROM recordings WHERE sha256 = ?");
  if (!q.ok()) return q.status();
  (void)q->Bind(1, sha);
  auto r = q->Step();
  if (!r.ok()) return r.status();
  if (!*r) return absl::NotFoundError(absl::StrCat("recording ", sha, " not found"));
  return q->Blob(0);
}

absl::StatusOr<std::string> SqliteStore::LatestRecordingSha(const std::string& serial) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(
      "SELECT recording_sha256 FROM runs WHERE serial = ? AND recording_sha256 IS NOT NULL "
      "ORDER BY run_id DESC LIMIT 1");
  if (!q.ok()) return q.status();
  (void)q->Bind(1, serial);
  auto r = q->Step();
  if (!r.ok()) return r.status();
  if (!*r) return absl::NotFoundError(absl::StrCat("serial '", serial, "' has no stored raw recording"));
  return q->Text(0);
}

absl::Status SqliteStore::InsertPointsLocked(int64_t run_id, const std::vector<HfPointRow>& points) {
  auto ins = writer_->Prepare(
      "INSERT INTO hf_points (run_id, idx, point_id, id_a, iq_a, speed_rpm, ld_h, lq_h, ldq_h, ld_h_std, "
      "lq_h_std, ldq_h_std, temperature_c, reliable) VALUES (?,?,?,?,?,?,?,?,?,?,?,?,?,?)");
  if (!ins.ok()) return ins.status();
  for (size_t k = 0; k < points.size(); ++k) {
    const auto& p = points[k];
    if (auto s = ins->BindAll({run_id, static_cast<int64_t>(k), p.point_id, p.id_a, p.iq_a, p.speed_rpm, p.ld_h,
                               p.lq_h, p.ldq_h ? SqlValue(*p.ldq_h) : SqlValue(nullptr), p.ld_h_std, p.lq_h_std,
                               p.ldq_h_std, p.temperature_c, int64_t{p.reliable ? 1 : 0}});
        !s.ok()) {
      return s;
    }
    if (auto r = ins->Step(); !r.ok()) return r.status();
    (void)ins->Reset();
  }
  return absl::OkStatus();
}

absl::StatusOr<std::vector<HfPointRow>> SqliteStore::PointsLocked(int64_t run_id) {
  auto p = writer_->Prepare(
      "SELECT point_id, id_a, iq_a, speed_rpm, ld_h, lq_h, ldq_h, ld_h_std, lq_h_std, ldq_h_std, temperature_c, "
      "reliable FROM hf_points WHERE run_id = ? ORDER BY idx");
  if (!p.ok()) return p.status();
  (void)p->Bind(1, run_id);
  std::vector<HfPointRow> out;
  while (true) {
    auto r = p->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    HfPointRow h;
    h.point_id = p->Text(0);
    h.id_a = p->Double(1); h.iq_a = p->Double(2); h.speed_rpm = p->Double(3);
    h.ld_h = p->Double(4); h.lq_h = p->Double(5);
    if (!p->IsNull(6)) h.ldq_h = p->Double(6);
    h.ld_h_std = p->Double(7); h.lq_h_std = p->Double(8); h.ldq_h_std = p->Double(9);
    h.temperature_c = p->Double(10); h.reliable = p->Int(11) != 0;
    out.push_back(h);
  }
  return out;
}

absl::StatusOr<std::vector<MotorRow>> SqliteStore::AllMotors() {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare("SELECT serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc FROM motors ORDER BY serial");
  if (!q.ok()) return q.status();
  std::vector<MotorRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back({q->Text(0), static_cast<int>(q->Int(1)), q->Double(2), q->Double(3), q->Text(4)});
  }
  return out;
}

absl::StatusOr<std::vector<RunRow>> SqliteStore::AllRuns() {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(
      "SELECT run_id, serial, station, kind, COALESCE(recording_sha256, ''), created_utc, COALESCE(idempotency_key, '') "
      "FROM runs ORDER BY run_id");
  if (!q.ok()) return q.status();
  std::vector<RunRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back({q->Int(0), q->Text(1), q->Text(2), q->Text(3), q->Text(4), q->Text(5), q->Text(6)});
  }
  return out;
}

absl::StatusOr<std::vector<HfPointRow>> SqliteStore::RunPoints(int64_t run_id) {
  std::lock_guard<std::mutex> lock(write_mu_);
  return PointsLocked(run_id);
}

absl::StatusOr<RecordingRow> SqliteStore::GetRecordingRow(const std::string& sha) {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare("SELECT size_bytes, zlib_data FROM recordings WHERE sha256 = ?");
  if (!q.ok()) return q.status();
  (void)q->Bind(1, sha);
  auto r = q->Step();
  if (!r.ok()) return r.status();
  if (!*r) return absl::NotFoundError(absl::StrCat("recording ", sha, " not found"));
  return RecordingRow{sha, q->Int(0), q->Blob(1)};
}

absl::StatusOr<std::vector<CalibrationRow>> SqliteStore::AllCalibrations() {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(absl::StrCat(kCalCols, "ORDER BY serial, version"));
  if (!q.ok()) return q.status();
  std::vector<CalibrationRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back(ReadCal(*q));
  }
  return out;
}

absl::Status SqliteStore::ImportMotor(const MotorRow& m) {
  std::lock_guard<std::mutex> lock(write_mu_);
  return writer_->Transaction([&]() -> absl::Status {
    auto q = writer_->Prepare(
        "INSERT INTO motors (serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc) VALUES (?,?,?,?,?)");
    if (!q.ok()) return q.status();
    if (auto s = q->BindAll({m.serial, int64_t{m.pole_pairs}, m.rs_ohm, m.psi_pm_wb, m.created_utc}); !s.ok()) return s;
    auto r = q->Step();
    return r.ok() ? absl::OkStatus() : r.status();
  });
}

absl::Status SqliteStore::ImportRun(const RunRow& run, const std::vector<HfPointRow>& points,
                                    const RecordingRow* rec) {
  std::lock_guard<std::mutex> lock(write_mu_);
  return writer_->Transaction([&]() -> absl::Status {
    if (rec) {
      auto q = writer_->Prepare("INSERT OR IGNORE INTO recordings (sha256, size_bytes, zlib_data) VALUES (?,?,?)");
      if (!q.ok()) return q.status();
      if (auto s = q->BindAll({rec->sha256, rec->size_bytes, rec->zlib_data}); !s.ok()) return s;
      if (auto r = q->Step(); !r.ok()) return r.status();
    }
    auto q = writer_->Prepare(
        "INSERT INTO runs (run_id, serial, station, kind, recording_sha256, created_utc, idempotency_key) "
        "VALUES (?,?,?,?,?,?,?)");
    if (!q.ok()) return q.status();
    if (auto s = q->BindAll({run.run_id, run.serial, run.station, run.kind,
                             run.recording_sha256.empty() ? SqlValue(nullptr) : SqlValue(run.recording_sha256),
                             run.created_utc,
                             run.idempotency_key.empty() ? SqlValue(nullptr) : SqlValue(run.idempotency_key)});
        !s.ok()) {
      return s;
    }
    if (auto r = q->Step(); !r.ok()) return r.status();
    return InsertPointsLocked(run.run_id, points);
  });
}

absl::Status SqliteStore::ImportCalibration(const CalibrationRow& c) {
  std::lock_guard<std::mutex> lock(write_mu_);
  return writer_->Transaction([&]() -> absl::Status {
    auto ins = writer_->Prepare(
        "INSERT INTO calibrations (serial, version, run_id, created_utc, model, psi_pm_wb, rms_relative, verdict, "
        "calibration_json, model_pb) VALUES (?,?,?,?,?,?,?,?,?,?)");
    if (!ins.ok()) return ins.status();
    if (auto s = ins->BindAll({c.serial, int64_t{c.version}, c.run_id ? SqlValue(c.run_id) : SqlValue(nullptr),
                               c.created_utc, c.model, c.psi_pm_wb, c.rms_relative, c.verdict, c.calibration_json,
                               BlobOrNull(c.model_pb)});
        !s.ok()) {
      return s;
    }
    auto r = ins->Step();
    return r.ok() ? absl::OkStatus() : r.status();
  });
}

absl::StatusOr<std::vector<ReleaseRow>> SqliteStore::AllReleases() {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(
      "SELECT serial, version, released_by, released_utc FROM releases ORDER BY serial, version");
  if (!q.ok()) return q.status();
  std::vector<ReleaseRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back({q->Text(0), static_cast<int>(q->Int(1)), q->Text(2), q->Text(3)});
  }
  return out;
}

absl::StatusOr<std::vector<AuditRow>> SqliteStore::AllAudit() {
  std::lock_guard<std::mutex> lock(write_mu_);
  auto q = writer_->Prepare(
      "SELECT id, utc, identity, role, peer, request_id, rpc, serial, detail FROM audit ORDER BY id");
  if (!q.ok()) return q.status();
  std::vector<AuditRow> out;
  while (true) {
    auto r = q->Step();
    if (!r.ok()) return r.status();
    if (!*r) break;
    out.push_back({q->Int(0), q->Text(1), q->Text(2), q->Text(3), q->Text(4), q->Text(5), q->Text(6), q->Text(7),
                   q->Text(8)});
  }
  return out;
}

absl::Status SqliteStore::ImportTrail(const std::vector<ReleaseRow>& releases, const std::vector<AuditRow>& audit,
                                      const std::vector<ChainRow>& chain,
                                      const std::vector<ReleaseLinkRow>& release_chain) {
  std::lock_guard<std::mutex> lock(write_mu_);
  return writer_->Transaction([&]() -> absl::Status {
    auto rel = writer_->Prepare("INSERT INTO releases (serial, version, released_by, released_utc) VALUES (?,?,?,?)");
    if (!rel.ok()) return rel.status();
    for (const auto& r : releases) {
      if (auto s = rel->BindAll({r.serial, int64_t{r.version}, r.released_by, r.released_utc}); !s.ok()) return s;
      if (auto x = rel->Step(); !x.ok()) return x.status();
      (void)rel->Reset();
    }
    auto au = writer_->Prepare(
        "INSERT INTO audit (id, utc, identity, role, peer, request_id, rpc, serial, detail) VALUES (?,?,?,?,?,?,?,?,?)");
    if (!au.ok()) return au.status();
    for (const auto& a : audit) {
      if (auto s = au->BindAll({a.id, a.utc, a.identity, a.role, a.peer, a.request_id, a.rpc, a.serial, a.detail});
          !s.ok()) {
        return s;
      }
      if (auto x = au->Step(); !x.ok()) return x.status();
      (void)au->Reset();
    }
    auto ch = writer_->Prepare(
        "INSERT INTO calibration_chain (serial, version, prev_sha256, row_sha256) VALUES (?,?,?,?)");
    if (!ch.ok()) return ch.status();
    for (const auto& l : chain) {
      if (auto s = ch->BindAll({l.serial, int64_t{l.version}, l.prev_sha256, l.row_sha256}); !s.ok()) return s;
      if (auto x = ch->Step(); !x.ok()) return x.status();
      (void)ch->Reset();
    }
    auto rc = writer_->Prepare(
        "INSERT INTO release_chain (seq, serial, version, calibration_sha256, prev_sha256, row_sha256) "
        "VALUES (?,?,?,?,?,?)");
    if (!rc.ok()) return rc.status();
    for (const auto& l : release_chain) {
      if (auto s = rc->BindAll({l.seq, l.serial, int64_t{l.version}, l.calibration_sha256, l.prev_sha256,
                                l.row_sha256});
          !s.ok()) {
        return s;
      }
      if (auto x = rc->Step(); !x.ok()) return x.status();
      (void)rc->Reset();
    }
    return absl::OkStatus();
  });
}

absl::Status SqliteStore::Backup(const std::string& dest_path) {
  std::lock_guard<std::mutex> lock(write_mu_);
  return writer_->BackupTo(dest_path);
}

}  // namespace fluxcal::storage
