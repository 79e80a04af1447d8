#include "storage/postgres_store.h"

#include <libpq-fe.h>

#include <cstdlib>
#include <optional>

#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace fluxcal::storage {
namespace {


// The migration after which releases are chained.
constexpr int kReleaseChainVersion = 7;
// The migration that converts stored JSON to the binary model.
constexpr int kBinaryModelVersion = 8;

// Any constants: the advisory locks that serialise migrations, and appends
// to the one release chain, across servers.
constexpr int64_t kMigrationLock = 0x666c7578;
constexpr int64_t kReleaseChainLock = 0x666c7572;

struct ResultDeleter {
  void operator()(PGresult* r) const { PQclear(r); }
};
using Result = std::unique_ptr<PGresult, ResultDeleter>;

// One bound parameter: text, binary (bytea) or NULL.
struct Param {
  std::optional<std::string> value;
  bool binary = false;
};
Param T(const std::string& s) { return {s, false}; }
Param I(int64_t v) { return {std::to_string(v), false}; }
// 17 significant digits: every double round-trips exactly.
Param D(double v) { return {absl::StrFormat("%.17g", v), false}; }
Param Null() { return {std::nullopt, false}; }
Param B(const std::vector<uint8_t>& b) { return {std::string(b.begin(), b.end()), true}; }
// A bytea from a string of bytes; NULL when empty.
Param BytesOrNull(const std::string& b) { return b.empty() ? Param{std::nullopt, false} : Param{b, true}; }

absl::Status PgError(PGconn* c, const PGresult* r, std::string_view what) {
  const char* state = r ? PQresultErrorField(r, PG_DIAG_SQLSTATE) : nullptr;
  std::string detail = r ? PQresultErrorMessage(r) : PQerrorMessage(c);
  while (!detail.empty() && (detail.back() == '\n' || detail.back() == ' ')) detail.pop_back();
  const std::string msg = absl::StrCat("postgresql: ", std::string(what), ": ", detail);
  const std::string code = state ? state : "";
  if (PQstatus(c) != CONNECTION_OK || absl::StartsWith(code, "08") || absl::StartsWith(code, "57P")) {
    return absl::UnavailableError(msg);
  }
  if (absl::StartsWith(code, "23")) return absl::AlreadyExistsError(msg);
  if (code == "40001" || code == "40P01") return absl::AbortedError(msg);
  if (code == "P0001") return absl::FailedPreconditionError(msg);
  return absl::InternalError(msg);
}

absl::StatusOr<Result> Exec(PGconn* c, const char* sql, const std::vector<Param>& params = {},
                            int result_format = 0) {
  std::vector<const char*> values(params.size());
  std::vector<int> lengths(params.size()), formats(params.size());
  for (size_t k = 0; k < params.size(); ++k) {
    values[k] = params[k].value ? params[k].value->data() : nullptr;
    lengths[k] = params[k].value ? static_cast<int>(params[k].value->size()) : 0;
    formats[k] = params[k].binary ? 1 : 0;
  }
  Result r(params.empty() && result_format == 0
               ? PQexec(c, sql)
               : PQexecParams(c, sql, static_cast<int>(params.size()), nullptr, values.data(), lengths.data(),
                              formats.data(), result_format));
  const auto st = r ? PQresultStatus(r.get()) : PGRES_FATAL_ERROR;
  if (st != PGRES_COMMAND_OK && st != PGRES_TUPLES_OK) {
    std::string what(sql);
    if (what.size() > 80) what = what.substr(0, 80) + "...";
    return PgError(c, r.get(), what);
  }
  return r;
}

std::string Text(const PGresult* r, int row, int col) {
  return std::string(PQgetvalue(r, row, col), PQgetlength(r, row, col));
}
int64_t Int(const PGresult* r, int row, int col) { return std::strtoll(PQgetvalue(r, row, col), nullptr, 10); }
double Double(const PGresult* r, int row, int col) { return std::strtod(PQgetvalue(r, row, col), nullptr); }
bool IsNull(const PGresult* r, int row, int col) { return PQgetisnull(r, row, col) != 0; }

constexpr char kCalCols[] =
    "SELECT serial, version, COALESCE(run_id, 0), created_utc, model, psi_pm_wb, rms_relative, verdict, "
    "calibration_json, model_pb FROM calibrations ";

// A bytea column of a text-format result (hex, "\\x0a1b..").
std::string Bytes(const PGresult* r, int row, int col) {
  if (IsNull(r, row, col)) return std::string();
  size_t n = 0;
  unsigned char* b = PQunescapeBytea(reinterpret_cast<const unsigned char*>(PQgetvalue(r, row, col)), &n);
  if (b == nullptr) return std::string();
  std::string out(reinterpret_cast<const char*>(b), n);
  PQfreemem(b);
  return out;
}

CalibrationRow ReadCal(const PGresult* r, int i) {
  CalibrationRow c;
  c.serial = Text(r, i, 0); c.version = static_cast<int>(Int(r, i, 1)); c.run_id = Int(r, i, 2);
  c.created_utc = Text(r, i, 3); c.model = Text(r, i, 4); c.psi_pm_wb = Double(r, i, 5);
  c.rms_relative = Double(r, i, 6); c.verdict = Text(r, i, 7); c.calibration_json = Text(r, i, 8);
  c.model_pb = Bytes(r, i, 9);
  return c;
}

constexpr char kConversionCols[] =
    "SELECT serial, version, json_sha256, row_sha256, converted_utc FROM calibration_conversions ";

ConversionRow ReadConversion(const PGresult* r, int i) {
  return {Text(r, i, 0), static_cast<int>(Int(r, i, 1)), Text(r, i, 2), Text(r, i, 3), Text(r, i, 4)};
}

absl::Status InsertConversion(PGconn* c, const ConversionRow& x) {
  return Exec(c,
              "INSERT INTO calibration_conversions (serial, version, json_sha256, row_sha256, converted_utc) "
              "VALUES ($1,$2,$3,$4,$5)",
              {T(x.serial), I(x.version), T(x.json_sha256), T(x.row_sha256), T(x.converted_utc)})
      .status();
}

// COPY text format: backslash, tab, newline and carriage return escaped.
void AppendCopyText(std::string* out, const std::string& s) {
  for (char ch : s) {
    switch (ch) {
      case '\\': out->append("\\\\"); break;
      case '\t': out->append("\\t"); break;
      case '\n': out->append("\\n"); break;
      case '\r': out->append("\\r"); break;
      default: out->push_back(ch);
    }
  }
}

// All points of a run in one COPY (one round trip for any number of points).
absl::Status CopyPoints(PGconn* c, int64_t run_id, const std::vector<HfPointRow>& points) {
  if (points.empty()) return absl::OkStatus();
  Result r(PQexec(c,
                  "COPY hf_points (run_id, idx, point_id, id_a, iq_a, speed_rpm, ld_h, lq_h, ldq_h, ld_h_std, "
                  "lq_h_std, ldq_h_std, temperature_c, reliable) FROM STDIN"));
  if (!r || PQresultStatus(r.get()) != PGRES_COPY_IN) return PgError(c, r.get(), "COPY hf_points");
  std::string buf;
  buf.reserve(points.size() * 200);
  for (size_t k = 0; k < points.size(); ++k) {
    const auto& p = points[k];
    absl::StrAppend(&buf, run_id, "\t", k, "\t");
    AppendCopyText(&buf, p.point_id);
    absl::StrAppendFormat(&buf, "\t%.17g\t%.17g\t%.17g\t%.17g\t%.17g\t", p.id_a, p.iq_a, p.speed_rpm, p.ld_h, p.lq_h);
    if (p.ldq_h) absl::StrAppendFormat(&buf, "%.17g", *p.ldq_h); else buf.append("\\N");
    absl::StrAppendFormat(&buf, "\t%.17g\t%.17g\t%.17g\t%.17g\t%d\n", p.ld_h_std, p.lq_h_std, p.ldq_h_std,
                          p.temperature_c, p.reliable ? 1 : 0);
  }
  if (PQputCopyData(c, buf.data(), static_cast<int>(buf.size())) != 1 || PQputCopyEnd(c, nullptr) != 1) {
    return PgError(c, nullptr, "COPY hf_points data");
  }
  absl::Status st;
  while (PGresult* res = PQgetResult(c)) {
    Result rr(res);
    if (PQresultStatus(res) != PGRES_COMMAND_OK && st.ok()) st = PgError(c, res, "COPY hf_points");
  }
  return st;
}

std::vector<HfPointRow> ReadPoints(const PGresult* r) {
  std::vector<HfPointRow> out;
  out.reserve(PQntuples(r));
  for (int i = 0; i < PQntuples(r); ++i) {
    HfPointRow h;
    h.point_id = Text(r, i, 0);
    h.id_a = Double(r, i, 1); h.iq_a = Double(r, i, 2); h.speed_rpm = Double(r, i, 3);
    h.ld_h = Double(r, i, 4); h.lq_h = Double(r, i, 5);
    if (!IsNull(r, i, 6)) h.ldq_h = Double(r, i, 6);
    h.ld_h_std = Double(r, i, 7); h.lq_h_std = Double(r, i, 8); h.ldq_h_std = Double(r, i, 9);
    h.temperature_c = Double(r, i, 10); h.reliable = Int(r, i, 11) != 0;
    out.push_back(h);
  }
  return out;
}

constexpr char kPointsOfRun[] =
    "SELECT point_id, id_a, iq_a, speed_rpm, ld_h, lq_h, ldq_h, ld_h_std, lq_h_std, ldq_h_std, temperature_c, "
    "reliable FROM hf_points WHERE run_id = $1 ORDER BY idx";

// Inserts `audit` (if any) inside the caller's transaction on `c`.
absl::Status InsertAudit(PGconn* c, const AuditContext* audit, int64_t written_id, bool replayed) {
  if (audit == nullptr) return absl::OkStatus();
  const AuditRow& a = audit->row;
  return Exec(c,
              "INSERT INTO audit (utc, identity, role, peer, request_id, rpc, serial, detail) "
              "VALUES ($1,$2,$3,$4,$5,$6,$7,$8)",
              {T(NowUtc()), T(a.identity), T(a.role), T(a.peer), T(a.request_id), T(a.rpc), T(a.serial),
               T(audit->detail ? audit->detail(written_id, replayed) : a.detail)})
      .status();
}

// Appends the link of release `r` to the release chain inside the caller's
// transaction on `c`, which holds kReleaseChainLock (Release, and the v7
// migration for releases stored before it).
absl::Status AppendReleaseLink(PGconn* c, const ReleaseRow& r) {
  // The released version's hash: its chain link, or its content for a
  // version from before the chain.
  auto l = Exec(c, "SELECT row_sha256 FROM calibration_chain WHERE serial = $1 AND version = $2",
                {T(r.serial), I(r.version)});
  if (!l.ok()) return l.status();
  std::string calibration_sha;
  if (PQntuples(l->get()) > 0) {
    calibration_sha = Text(l->get(), 0, 0);
  } else {
    const std::string sql = absl::StrCat(kCalCols, "WHERE serial = $1 AND version = $2");
    auto q = Exec(c, sql.c_str(), {T(r.serial), I(r.version)});
    if (!q.ok()) return q.status();
    if (PQntuples(q->get()) == 0) {
      return absl::NotFoundError(absl::StrCat("serial '", r.serial, "' has no calibration version ", r.version));
    }
    calibration_sha = VersionSha256(ReadCal(q->get(), 0), nullptr);
  }
  auto last = Exec(c, "SELECT seq, row_sha256 FROM release_chain ORDER BY seq DESC LIMIT 1");
  if (!last.ok()) return last.status();
  const bool any = PQntuples(last->get()) > 0;
  const int64_t seq = any ? Int(last->get(), 0, 0) + 1 : 1;
  const std::string prev = any ? Text(last->get(), 0, 1) : std::string();
  return Exec(c,
              "INSERT INTO release_chain (seq, serial, version, calibration_sha256, prev_sha256, row_sha256) "
              "VALUES ($1,$2,$3,$4,$5,$6)",
              {I(seq), T(r.serial), I(r.version), T(calibration_sha), T(prev),
               T(ReleaseRowSha256(prev, seq, r, calibration_sha))})
      .status();
}

// The v8 migration's data step inside the migration's transaction on `c`:
// every version stored as JSON converted where ConvertStoredJson allows,
// with its record and one audit row (SqliteStore::ConvertStoredJsonLocked
// is the same on SQLite).
absl::Status ConvertStoredJsonIn(PGconn* c, const JsonToModelFn& json_to_model) {
  auto keys = Exec(c, "SELECT serial, version FROM calibrations ORDER BY serial COLLATE \"C\", version");
  if (!keys.ok()) return keys.status();
  const int n = PQntuples(keys->get());
  if (n == 0 || !json_to_model) return absl::OkStatus();
  // Versions are immutable; the migration is the one sanctioned rewrite,
  // its trigger off only inside this transaction.
  if (auto r = Exec(c, "ALTER TABLE calibrations DISABLE TRIGGER calibrations_no_update"); !r.ok()) return r.status();
  const std::string now = NowUtc();
  const std::string sql = absl::StrCat(kCalCols, "WHERE serial = $1 AND version = $2");
  int converted = 0;
  std::string digest;
  for (int i = 0; i < n; ++i) {
    const std::string serial = Text(keys->get(), i, 0);
    const int64_t version = Int(keys->get(), i, 1);
    auto q = Exec(c, sql.c_str(), {T(serial), I(version)});
    if (!q.ok()) return q.status();
    if (PQntuples(q->get()) == 0) continue;
    const CalibrationRow row = ReadCal(q->get(), 0);
    auto l = Exec(c, "SELECT serial, version, prev_sha256, row_sha256 FROM calibration_chain "
                     "WHERE serial = $1 AND version = $2",
                  {T(serial), I(version)});
    if (!l.ok()) return l.status();
    std::optional<ChainRow> link;
    if (PQntuples(l->get()) > 0) {
      link = ChainRow{Text(l->get(), 0, 0), static_cast<int>(Int(l->get(), 0, 1)), Text(l->get(), 0, 2),
                      Text(l->get(), 0, 3)};
    }
    auto conv = ConvertStoredJson(row, link ? &*link : nullptr, json_to_model, now);
    if (!conv) continue;
    if (auto r = Exec(c, "UPDATE calibrations SET calibration_json = '', model_pb = $1 WHERE serial = $2 AND version = $3",
                      {BytesOrNull(conv->row.model_pb), T(serial), I(version)});
        !r.ok()) {
      return r.status();
    }
    if (auto st = InsertConversion(c, conv->record); !st.ok()) return st;
    const ConversionRow& x = conv->record;
    absl::StrAppend(&digest, x.serial, "\t", x.version, "\t", x.json_sha256, "\t", x.row_sha256, "\n");
    ++converted;
  }
  if (auto r = Exec(c, "ALTER TABLE calibrations ENABLE TRIGGER calibrations_no_update"); !r.ok()) return r.status();
  AuditContext audit;
  audit.row = {0, "", "fluxcal", "admin", "", "", "migrate", "", ConversionAuditDetail(converted, n, digest)};
  return InsertAudit(c, &audit, 0, false);
}

}  // namespace

absl::StatusOr<std::unique_ptr<PostgresStore>> PostgresStore::Open(const std::string& url_in, int max_connections,
                                                                   bool create, JsonToModelFn json_to_model) {
  // A database that does not answer must fail a call, not hang it: bound
  // the connect unless the URI says otherwise.
  std::string url = url_in;
  if (url.find("connect_timeout") == std::string::npos) {
    url += url.find('?') == std::string::npos ? "?connect_timeout=5" : "&connect_timeout=5";
  }
  std::unique_ptr<PostgresStore> s(new PostgresStore(url, std::max(1, max_connections)));
  if (auto st = s->Migrate(create, json_to_model); !st.ok()) return st;
  return s;
}

PostgresStore::~PostgresStore() {
  for (PGconn* c : idle_) PQfinish(c);
}

absl::StatusOr<PGconn*> PostgresStore::Acquire() {
  std::unique_lock<std::mutex> lock(mu_);
  cv_.wait(lock, [&] { return !idle_.empty() || open_ < max_; });
  if (!idle_.empty()) {
    PGconn* c = idle_.back();
    idle_.pop_back();
    return c;
  }
  ++open_;
  lock.unlock();
  PGconn* c = PQconnectdb(url_.c_str());
  if (PQstatus(c) != CONNECTION_OK) {
    const std::string msg = PQerrorMessage(c);
    PQfinish(c);
    std::lock_guard<std::mutex> relock(mu_);
    --open_;
    cv_.notify_one();
    return absl::UnavailableError(absl::StrCat("postgresql: cannot connect: ", msg));
  }
  // Quiet notices (e.g. "relation already exists, skipping").
  PQsetNoticeProcessor(c, [](void*, const char*) {}, nullptr);
  return c;
}

void PostgresStore::Release(PGconn* c) {
  std::lock_guard<std::mutex> lock(mu_);
  if (PQstatus(c) != CONNECTION_OK || PQtransactionStatus(c) != PQTRANS_IDLE) {
    PQfinish(c);   // broken or left inside a transaction: never reuse
    --open_;
  } else {
    idle_.push_back(c);
  }
  cv_.notify_one();
}

absl::Status PostgresStore::WithConn(const std::function<absl::Status(PGconn*)>& fn) {
  auto c = Acquire();
  if (!c.ok()) return c.status();
  absl::Status st = fn(*c);
  Release(*c);
  return st;
}

absl::Status PostgresStore::WithTransaction(const std::function<absl::Status(PGconn*)>& fn) {
  return WithConn([&](PGconn* c) -> absl::Status {
    if (auto r = Exec(c, "BEGIN"); !r.ok()) return r.status();
    absl::Status st = fn(c);
    if (st.ok()) {
      auto r = Exec(c, "COMMIT");
      if (r.ok()) return absl::OkStatus();
      st = r.status();
    }
    (void)Exec(c, "ROLLBACK");
    return st;
  });
}

absl::Status PostgresStore::Migrate(bool create, const JsonToModelFn& json_to_model) {
  return WithTransaction([&](PGconn* c) -> absl::Status {
    if (auto r = Exec(c, "SELECT pg_advisory_xact_lock($1)", {I(kMigrationLock)}); !r.ok()) return r.status();
    if (!create) {
      // A database without fluxcal's tables is refused, not turned into a store.
      auto q = Exec(c, "SELECT to_regclass('schema_version') IS NOT NULL");
      if (!q.ok()) return q.status();
      if (Text(q->get(), 0, 0) != "t") {
        return absl::NotFoundError("postgresql: the database holds no fluxcal store (no schema_version table)");
      }
    }
    if (auto r = Exec(c, "CREATE TABLE IF NOT EXISTS schema_version (version INTEGER NOT NULL)"); !r.ok()) {
      return r.status();
    }
    auto q = Exec(c, "SELECT COALESCE(MAX(version), 0) FROM schema_version");
    if (!q.ok()) return q.status();
    int v = static_cast<int>(Int(q->get(), 0, 0));
    if (v > kSchemaVersion) {
      return absl::FailedPreconditionError(absl::StrCat("database schema version ", v,
                                                        " is newer than this fluxcal (", kSchemaVersion, ")"));
    }
    for (; v < kSchemaVersion; ++v) {
      if (auto r = Exec(c, PostgresMigrations()[v].c_str()); !r.ok()) return r.status();
      if (v + 1 == kReleaseChainVersion) {
        // Releases stored before the chain join it now, oldest first.
        auto q = Exec(c, "SELECT serial, version, released_by, released_utc FROM releases "
                         "ORDER BY released_utc, serial COLLATE \"C\", version");
        if (!q.ok()) return q.status();
        for (int i = 0; i < PQntuples(q->get()); ++i) {
          const ReleaseRow row{Text(q->get(), i, 0), static_cast<int>(Int(q->get(), i, 1)), Text(q->get(), i, 2),
                               Text(q->get(), i, 3)};
          if (auto st = AppendReleaseLink(c, row); !st.ok()) return st;
        }
      }
      if (v + 1 == kBinaryModelVersion) {
        if (auto st = ConvertStoredJsonIn(c, json_to_model); !st.ok()) return st;
      }
      if (auto r = Exec(c, "INSERT INTO schema_version (version) VALUES ($1)", {I(v + 1)}); !r.ok()) return r.status();
    }
    return absl::OkStatus();
  });
}

absl::StatusOr<int> PostgresStore::SchemaVersion() {
  int v = 0;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT MAX(version) FROM schema_version");
    if (!q.ok()) return q.status();
    v = static_cast<int>(Int(q->get(), 0, 0));
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return v;
}

absl::StatusOr<int64_t> PostgresStore::IngestHfRun(const MotorRow& m, const std::string& station,
                                                   const std::string& kind, const std::vector<HfPointRow>& points,
                                                   const std::string& sha, const std::vector<uint8_t>& blob,
                                                   int64_t recording_bytes, const std::string& key, bool* replayed,
                                                   const AuditContext* audit) {
  int64_t run_id = 0;
  if (replayed != nullptr) *replayed = false;
  auto st = WithTransaction([&](PGconn* c) -> absl::Status {
    if (replayed != nullptr) *replayed = false;
    if (auto r = Exec(c,
                      "INSERT INTO motors (serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc) VALUES ($1,$2,$3,$4,$5) "
                      "ON CONFLICT (serial) DO UPDATE SET pole_pairs = EXCLUDED.pole_pairs, rs_ohm = EXCLUDED.rs_ohm, "
                      "psi_pm_wb = EXCLUDED.psi_pm_wb",
                      {T(m.serial), I(m.pole_pairs), D(m.rs_ohm), D(m.psi_pm_wb), T(NowUtc())});
        !r.ok()) {
      return r.status();
    }
    // The upsert above holds the motor row's lock until commit, so ingests
    // of one serial are serialised and a retry sees the first run.
    if (!key.empty()) {
      auto q = Exec(c, "SELECT run_id FROM runs WHERE serial = $1 AND idempotency_key = $2", {T(m.serial), T(key)});
      if (!q.ok()) return q.status();
      if (PQntuples(q->get()) > 0) {
        run_id = Int(q->get(), 0, 0);
        if (replayed != nullptr) *replayed = true;
        return InsertAudit(c, audit, run_id, true);
      }
    }
    if (!sha.empty()) {
      if (auto r = Exec(c,
                        "INSERT INTO recordings (sha256, size_bytes, zlib_data) VALUES ($1,$2,$3) "
                        "ON CONFLICT (sha256) DO NOTHING",
                        {T(sha), I(recording_bytes), B(blob)});
          !r.ok()) {
        return r.status();
      }
    }
    auto run = Exec(c,
                    "INSERT INTO runs (serial, station, kind, recording_sha256, created_utc, idempotency_key) "
                    "VALUES ($1,$2,$3,$4,$5,$6) RETURNING run_id",
                    {T(m.serial), T(station), T(kind), sha.empty() ? Null() : T(sha), T(NowUtc()),
                     key.empty() ? Null() : T(key)});
    if (!run.ok()) return run.status();
    run_id = Int(run->get(), 0, 0);
    if (auto st = CopyPoints(c, run_id, points); !st.ok()) return st;
    return InsertAudit(c, audit, run_id, false);
  });
  if (!st.ok()) return st;
  return run_id;
}

absl::Status PostgresStore::Release(const std::string& serial, int version, const std::string& by,
                                    const AuditContext* audit) {
  return WithTransaction([&](PGconn* c) -> absl::Status {
    // One release chain for the store: appends from every server in turn.
    if (auto r = Exec(c, "SELECT pg_advisory_xact_lock($1)", {I(kReleaseChainLock)}); !r.ok()) return r.status();
    // FOR SHARE: the calibration row cannot change anyway (immutable), but
    // the lock orders concurrent releases of one version.
    auto q = Exec(c, "SELECT verdict FROM calibrations WHERE serial = $1 AND version = $2 FOR SHARE",
                  {T(serial), I(version)});
    if (!q.ok()) return q.status();
    if (PQntuples(q->get()) == 0) {
      return absl::NotFoundError(absl::StrCat("serial '", serial, "' has no calibration version ", version));
    }
    const std::string verdict = Text(q->get(), 0, 0);
    if (verdict != "pass") {
      return absl::FailedPreconditionError(
          absl::StrCat("version ", version, " of '", serial, "' has verdict '", verdict, "'; only 'pass' can be released"));
    }
    const ReleaseRow row{serial, version, by, NowUtc()};
    auto ins = Exec(c,
                    "INSERT INTO releases (serial, version, released_by, released_utc) VALUES ($1,$2,$3,$4) "
                    "ON CONFLICT DO NOTHING RETURNING version",
                    {T(row.serial), I(row.version), T(row.released_by), T(row.released_utc)});
    if (!ins.ok()) return ins.status();
    if (PQntuples(ins->get()) == 0) {
      return absl::AlreadyExistsError(absl::StrCat("version ", version, " of '", serial, "' is released already"));
    }
    if (auto st = AppendReleaseLink(c, row); !st.ok()) return st;
    return InsertAudit(c, audit, version, false);
  });
}

absl::StatusOr<int> PostgresStore::LatestReleasedVersion(const std::string& serial) {
  int v = 0;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT COALESCE(MAX(version), 0) FROM releases WHERE serial = $1", {T(serial)});
    if (!q.ok()) return q.status();
    v = static_cast<int>(Int(q->get(), 0, 0));
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return v;
}

absl::StatusOr<bool> PostgresStore::IsReleased(const std::string& serial, int version) {
  bool out = false;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT COUNT(*) FROM releases WHERE serial = $1 AND version = $2", {T(serial), I(version)});
    if (!q.ok()) return q.status();
    out = Int(q->get(), 0, 0) > 0;
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<ReleaseRow> PostgresStore::GetRelease(const std::string& serial, int version) {
  ReleaseRow out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT serial, version, released_by, released_utc FROM releases WHERE serial = $1 AND version = $2",
                  {T(serial), I(version)});
    if (!q.ok()) return q.status();
    if (PQntuples(q->get()) == 0) {
      return absl::NotFoundError(absl::StrCat("version ", version, " of '", serial, "' is not released"));
    }
    out = {Text(q->get(), 0, 0), static_cast<int>(Int(q->get(), 0, 1)), Text(q->get(), 0, 2), Text(q->get(), 0, 3)};
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<ReleaseLinkRow>> PostgresStore::ReleaseLinks(const std::string& where,
                                                                        const std::vector<std::string>& args) {
  std::vector<ReleaseLinkRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    const std::string sql = absl::StrCat(
        "SELECT seq, serial, version, calibration_sha256, prev_sha256, row_sha256 FROM release_chain ", where);
    std::vector<Param> params;
    for (const auto& a : args) params.push_back(T(a));
    auto q = Exec(c, sql.c_str(), params);
    if (!q.ok()) return q.status();
    const PGresult* r = q->get();
    for (int i = 0; i < PQntuples(r); ++i) {
      out.push_back({Int(r, i, 0), Text(r, i, 1), static_cast<int>(Int(r, i, 2)), Text(r, i, 3), Text(r, i, 4),
                     Text(r, i, 5)});
    }
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<ReleaseLinkRow>> PostgresStore::AllReleaseLinks() { return ReleaseLinks("ORDER BY seq", {}); }

absl::StatusOr<ReleaseLinkRow> PostgresStore::ReleaseLink(const std::string& serial, int version) {
  auto v = ReleaseLinks("WHERE serial = $1 AND version = $2::int", {serial, std::to_string(version)});
  if (!v.ok()) return v.status();
  if (v->empty()) return absl::NotFoundError(absl::StrCat(serial, " v", version, ": no release chain link"));
  return v->front();
}

absl::StatusOr<ReleaseLinkRow> PostgresStore::ReleaseLinkAt(int64_t seq) {
  auto v = seq > 0 ? ReleaseLinks("WHERE seq = $1::bigint", {std::to_string(seq)})
                   : ReleaseLinks("ORDER BY seq DESC LIMIT 1", {});
  if (!v.ok()) return v.status();
  if (v->empty()) return absl::NotFoundError(absl::StrCat("release chain: no link #", seq));
  return v->front();
}

absl::Status PostgresStore::AppendAudit(const AuditRow& a) {
  return WithConn([&](PGconn* c) -> absl::Status {
    auto r = Exec(c,
                  "INSERT INTO audit (utc, identity, role, peer, request_id, rpc, serial, detail) "
                  "VALUES ($1,$2,$3,$4,$5,$6,$7,$8)",
                  {T(NowUtc()), T(a.identity), T(a.role), T(a.peer), T(a.request_id), T(a.rpc), T(a.serial),
                   T(a.detail)});
    return r.ok() ? absl::OkStatus() : r.status();
  });
}

absl::StatusOr<std::vector<AuditRow>> PostgresStore::AuditOf(const std::string& serial) {
  std::vector<AuditRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c,
                  "SELECT id, utc, identity, role, peer, request_id, rpc, serial, detail FROM audit "
                  "WHERE serial = $1 ORDER BY id",
                  {T(serial)});
    if (!q.ok()) return q.status();
    for (int i = 0; i < PQntuples(q->get()); ++i) {
      const PGresult* r = q->get();
      out.push_back({Int(r, i, 0), Text(r, i, 1), Text(r, i, 2), Text(r, i, 3), Text(r, i, 4), Text(r, i, 5),
                     Text(r, i, 6), Text(r, i, 7), Text(r, i, 8)});
    }
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<ChainRow>> PostgresStore::AllChainRows() {
  std::vector<ChainRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT serial, version, prev_sha256, row_sha256 FROM calibration_chain ORDER BY serial, version");
    if (!q.ok()) return q.status();
    for (int i = 0; i < PQntuples(q->get()); ++i) {
      out.push_back({Text(q->get(), i, 0), static_cast<int>(Int(q->get(), i, 1)), Text(q->get(), i, 2),
                     Text(q->get(), i, 3)});
    }
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<ChainRow> PostgresStore::ChainLink(const std::string& serial, int version) {
  ChainRow out;
  bool found = false;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = version > 0
                 ? Exec(c, "SELECT serial, version, prev_sha256, row_sha256 FROM calibration_chain "
                           "WHERE serial = $1 AND version = $2", {T(serial), I(version)})
                 : Exec(c, "SELECT serial, version, prev_sha256, row_sha256 FROM calibration_chain "
                           "WHERE serial = $1 ORDER BY version DESC LIMIT 1", {T(serial)});
    if (!q.ok()) return q.status();
    if (PQntuples(q->get()) > 0) {
      found = true;
      out = {Text(q->get(), 0, 0), static_cast<int>(Int(q->get(), 0, 1)), Text(q->get(), 0, 2), Text(q->get(), 0, 3)};
    }
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  if (!found) return absl::NotFoundError(absl::StrCat("serial '", serial, "': no chain link"));
  return out;
}

absl::StatusOr<MotorRow> PostgresStore::GetMotor(const std::string& serial) {
  MotorRow m;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT pole_pairs, rs_ohm, psi_pm_wb, created_utc FROM motors WHERE serial = $1", {T(serial)});
    if (!q.ok()) return q.status();
    if (PQntuples(q->get()) == 0) return absl::NotFoundError(absl::StrCat("serial '", serial, "' not found"));
    m = MotorRow{serial, static_cast<int>(Int(q->get(), 0, 0)), Double(q->get(), 0, 1), Double(q->get(), 0, 2),
                 Text(q->get(), 0, 3)};
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return m;
}

absl::StatusOr<std::vector<HfPointRow>> PostgresStore::LatestRunPoints(const std::string& serial, int64_t* run_id) {
  std::vector<HfPointRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT MAX(run_id) FROM runs WHERE serial = $1", {T(serial)});
    if (!q.ok()) return q.status();
    if (IsNull(q->get(), 0, 0)) return absl::NotFoundError(absl::StrCat("serial '", serial, "' has no ingested run"));
    *run_id = Int(q->get(), 0, 0);
    auto p = Exec(c, kPointsOfRun, {I(*run_id)});
    if (!p.ok()) return p.status();
    out = ReadPoints(p->get());
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<int> PostgresStore::AddCalibration(const CalibrationRow& cr, const AuditContext* audit) {
  int version = 0;
  auto st = WithTransaction([&](PGconn* c) -> absl::Status {
    // The motor row lock serialises version assignment for this serial
    // across every process; READ COMMITTED then sees the previous commit.
    auto lock = Exec(c, "SELECT 1 FROM motors WHERE serial = $1 FOR UPDATE", {T(cr.serial)});
    if (!lock.ok()) return lock.status();
    if (PQntuples(lock->get()) == 0) return absl::NotFoundError(absl::StrCat("serial '", cr.serial, "' not found"));
    auto q = Exec(c, "SELECT COALESCE(MAX(version), 0) FROM calibrations WHERE serial = $1", {T(cr.serial)});
    if (!q.ok()) return q.status();
    version = static_cast<int>(Int(q->get(), 0, 0)) + 1;
    CalibrationRow row = cr;
    row.version = version;
    row.created_utc = NowUtc();
    auto ins = Exec(c,
                    "INSERT INTO calibrations (serial, version, run_id, created_utc, model, psi_pm_wb, rms_relative, "
                    "verdict, calibration_json, model_pb) VALUES ($1,$2,$3,$4,$5,$6,$7,$8,$9,$10)",
                    {T(cr.serial), I(version), cr.run_id ? I(cr.run_id) : Null(), T(row.created_utc), T(cr.model),
                     D(cr.psi_pm_wb), D(cr.rms_relative), T(cr.verdict), T(cr.calibration_json),
                     BytesOrNull(cr.model_pb)});
    if (!ins.ok()) return ins.status();
    auto prev = Exec(c, "SELECT row_sha256 FROM calibration_chain WHERE serial = $1 ORDER BY version DESC LIMIT 1",
                     {T(cr.serial)});
    if (!prev.ok()) return prev.status();
    const std::string prev_sha = PQntuples(prev->get()) > 0 ? Text(prev->get(), 0, 0) : std::string();
    auto link = Exec(c, "INSERT INTO calibration_chain (serial, version, prev_sha256, row_sha256) VALUES ($1,$2,$3,$4)",
                     {T(cr.serial), I(version), T(prev_sha), T(CalibrationRowSha256(prev_sha, row))});
    if (!link.ok()) return link.status();
    return InsertAudit(c, audit, version, false);
  });
  if (!st.ok()) return st;
  return version;
}

absl::StatusOr<CalibrationRow> PostgresStore::GetCalibration(const std::string& serial, int version) {
  CalibrationRow out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    const std::string sql = absl::StrCat(
        kCalCols, version > 0 ? "WHERE serial = $1 AND version = $2" : "WHERE serial = $1 ORDER BY version DESC LIMIT 1");
    auto q = version > 0 ? Exec(c, sql.c_str(), {T(serial), I(version)}) : Exec(c, sql.c_str(), {T(serial)});
    if (!q.ok()) return q.status();
    if (PQntuples(q->get()) == 0) {
      return absl::NotFoundError(version > 0
                                     ? absl::StrCat("serial '", serial, "' has no calibration version ", version)
                                     : absl::StrCat("serial '", serial, "' has no calibration"));
    }
    out = ReadCal(q->get(), 0);
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<CalibrationRow>> PostgresStore::LatestCalibrations() {
  std::vector<CalibrationRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    const std::string sql = absl::StrCat(
        kCalCols, "c WHERE version = (SELECT MAX(version) FROM calibrations d WHERE d.serial = c.serial) ORDER BY serial");
    auto q = Exec(c, sql.c_str());
    if (!q.ok()) return q.status();
    for (int i = 0; i < PQntuples(q->get()); ++i) out.push_back(ReadCal(q->get(), i));
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<MotorSummaryRow>> PostgresStore::ListMotors(const std::string& prefix, bool only_failed,
                                                                       int offset, int limit) {
  std::vector<MotorSummaryRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c,
                  "SELECT m.serial, COALESCE(c.version, 0), COALESCE(c.verdict, ''), "
                  "(SELECT COUNT(*) FROM runs r WHERE r.serial = m.serial), "
                  "COALESCE(c.created_utc, m.created_utc) FROM motors m "
                  "LEFT JOIN calibrations c ON c.serial = m.serial AND c.version = "
                  "(SELECT MAX(version) FROM calibrations d WHERE d.serial = m.serial) "
                  "WHERE left(m.serial, length($1::text)) = $1::text AND ($2::int = 0 OR c.verdict LIKE 'fail%') "
                  "ORDER BY m.serial COLLATE \"C\" LIMIT $3::bigint OFFSET $4::bigint",
                  {T(prefix), I(only_failed ? 1 : 0), I(limit), I(offset)});
    if (!q.ok()) return q.status();
    const PGresult* r = q->get();
    for (int i = 0; i < PQntuples(r); ++i) {
      out.push_back({Text(r, i, 0), Text(r, i, 2), Text(r, i, 4), static_cast<int>(Int(r, i, 1)),
                     static_cast<int>(Int(r, i, 3))});
    }
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<HistoryRow>> PostgresStore::History(const std::string& serial) {
  if (auto m = GetMotor(serial); !m.ok()) return m.status();
  std::vector<HistoryRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c,
                  "SELECT created_utc, kind, run_id, 0, COALESCE(recording_sha256, '') FROM runs WHERE serial = $1 "
                  "UNION ALL SELECT created_utc, 'calibration', COALESCE(run_id, 0), version, model || ' ' || verdict "
                  "FROM calibrations WHERE serial = $1 ORDER BY 1, 3, 4",
                  {T(serial)});
    if (!q.ok()) return q.status();
    const PGresult* r = q->get();
    for (int i = 0; i < PQntuples(r); ++i) {
      out.push_back({Text(r, i, 0), Text(r, i, 1), Text(r, i, 4), Int(r, i, 2), static_cast<int>(Int(r, i, 3))});
    }
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<RecordingRow> PostgresStore::GetRecordingRow(const std::string& sha) {
  RecordingRow out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    // Binary results: the bytea arrives as raw bytes, the text as text.
    auto q = Exec(c, "SELECT size_bytes::text, zlib_data FROM recordings WHERE sha256 = $1", {T(sha)}, 1);
    if (!q.ok()) return q.status();
    if (PQntuples(q->get()) == 0) return absl::NotFoundError(absl::StrCat("recording ", sha, " not found"));
    out.sha256 = sha;
    if (!absl::SimpleAtoi(Text(q->get(), 0, 0), &out.size_bytes)) return absl::DataLossError("recording size");
    const auto* p = reinterpret_cast<const uint8_t*>(PQgetvalue(q->get(), 0, 1));
    out.zlib_data.assign(p, p + PQgetlength(q->get(), 0, 1));
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<uint8_t>> PostgresStore::GetRecording(const std::string& sha) {
  auto r = GetRecordingRow(sha);
  if (!r.ok()) return r.status();
  return std::move(r->zlib_data);
}

absl::StatusOr<std::string> PostgresStore::LatestRecordingSha(const std::string& serial) {
  std::string out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c,
                  "SELECT recording_sha256 FROM runs WHERE serial = $1 AND recording_sha256 IS NOT NULL "
                  "ORDER BY run_id DESC LIMIT 1",
                  {T(serial)});
    if (!q.ok()) return q.status();
    if (PQntuples(q->get()) == 0) {
      return absl::NotFoundError(absl::StrCat("serial '", serial, "' has no stored raw recording"));
    }
    out = Text(q->get(), 0, 0);
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<MotorRow>> PostgresStore::AllMotors() {
  std::vector<MotorRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc FROM motors ORDER BY serial COLLATE \"C\"");
    if (!q.ok()) return q.status();
    const PGresult* r = q->get();
    for (int i = 0; i < PQntuples(r); ++i) {
      out.push_back({Text(r, i, 0), static_cast<int>(Int(r, i, 1)), Double(r, i, 2), Double(r, i, 3), Text(r, i, 4)});
    }
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<RunRow>> PostgresStore::AllRuns() {
  std::vector<RunRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT run_id, serial, station, kind, COALESCE(recording_sha256, ''), created_utc, "
                     "COALESCE(idempotency_key, '') FROM runs ORDER BY run_id");
    if (!q.ok()) return q.status();
    const PGresult* r = q->get();
    for (int i = 0; i < PQntuples(r); ++i) {
      out.push_back({Int(r, i, 0), Text(r, i, 1), Text(r, i, 2), Text(r, i, 3), Text(r, i, 4), Text(r, i, 5),
                     Text(r, i, 6)});
    }
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<HfPointRow>> PostgresStore::RunPoints(int64_t run_id) {
  std::vector<HfPointRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto p = Exec(c, kPointsOfRun, {I(run_id)});
    if (!p.ok()) return p.status();
    out = ReadPoints(p->get());
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<CalibrationRow>> PostgresStore::AllCalibrations() {
  std::vector<CalibrationRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    const std::string sql = absl::StrCat(kCalCols, "ORDER BY serial COLLATE \"C\", version");
    auto q = Exec(c, sql.c_str());
    if (!q.ok()) return q.status();
    for (int i = 0; i < PQntuples(q->get()); ++i) out.push_back(ReadCal(q->get(), i));
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::Status PostgresStore::ImportMotor(const MotorRow& m) {
  return WithTransaction([&](PGconn* c) -> absl::Status {
    return Exec(c, "INSERT INTO motors (serial, pole_pairs, rs_ohm, psi_pm_wb, created_utc) VALUES ($1,$2,$3,$4,$5)",
                {T(m.serial), I(m.pole_pairs), D(m.rs_ohm), D(m.psi_pm_wb), T(m.created_utc)})
        .status();
  });
}

absl::Status PostgresStore::ImportRun(const RunRow& run, const std::vector<HfPointRow>& points,
                                      const RecordingRow* rec) {
  return WithTransaction([&](PGconn* c) -> absl::Status {
    if (rec) {
      if (auto r = Exec(c,
                        "INSERT INTO recordings (sha256, size_bytes, zlib_data) VALUES ($1,$2,$3) "
                        "ON CONFLICT (sha256) DO NOTHING",
                        {T(rec->sha256), I(rec->size_bytes), B(rec->zlib_data)});
          !r.ok()) {
        return r.status();
      }
    }
    if (auto r = Exec(c,
                      "INSERT INTO runs (run_id, serial, station, kind, recording_sha256, created_utc, idempotency_key) "
                      "VALUES ($1,$2,$3,$4,$5,$6,$7)",
                      {I(run.run_id), T(run.serial), T(run.station), T(run.kind),
                       run.recording_sha256.empty() ? Null() : T(run.recording_sha256), T(run.created_utc),
                       run.idempotency_key.empty() ? Null() : T(run.idempotency_key)});
        !r.ok()) {
      return r.status();
    }
    if (auto st = CopyPoints(c, run.run_id, points); !st.ok()) return st;
    // Later runs continue after the imported ids.
    return Exec(c, "SELECT setval(pg_get_serial_sequence('runs', 'run_id'), (SELECT MAX(run_id) FROM runs))").status();
  });
}

absl::Status PostgresStore::ImportCalibration(const CalibrationRow& cr) {
  return WithTransaction([&](PGconn* c) -> absl::Status {
    return Exec(c,
                "INSERT INTO calibrations (serial, version, run_id, created_utc, model, psi_pm_wb, rms_relative, "
                "verdict, calibration_json, model_pb) VALUES ($1,$2,$3,$4,$5,$6,$7,$8,$9,$10)",
                {T(cr.serial), I(cr.version), cr.run_id ? I(cr.run_id) : Null(), T(cr.created_utc), T(cr.model),
                 D(cr.psi_pm_wb), D(cr.rms_relative), T(cr.verdict), T(cr.calibration_json),
                 BytesOrNull(cr.model_pb)})
        .status();
  });
}

absl::Status PostgresStore::ImportConversions(const std::vector<ConversionRow>& conversions) {
  return WithTransaction([&](PGconn* c) -> absl::Status {
    for (const auto& x : conversions) {
      if (auto st = InsertConversion(c, x); !st.ok()) return st;
    }
    return absl::OkStatus();
  });
}

absl::StatusOr<std::vector<ConversionRow>> PostgresStore::AllConversions() {
  std::vector<ConversionRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    const std::string sql = absl::StrCat(kConversionCols, "ORDER BY serial COLLATE \"C\", version");
    auto q = Exec(c, sql.c_str());
    if (!q.ok()) return q.status();
    for (int i = 0; i < PQntuples(q->get()); ++i) out.push_back(ReadConversion(q->get(), i));
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::optional<ConversionRow>> PostgresStore::Conversion(const std::string& serial, int version) {
  std::optional<ConversionRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    const std::string sql = absl::StrCat(kConversionCols, "WHERE serial = $1 AND version = $2");
    auto q = Exec(c, sql.c_str(), {T(serial), I(version)});
    if (!q.ok()) return q.status();
    if (PQntuples(q->get()) > 0) out = ReadConversion(q->get(), 0);
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<ReleaseRow>> PostgresStore::AllReleases() {
  std::vector<ReleaseRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT serial, version, released_by, released_utc FROM releases "
                     "ORDER BY serial COLLATE \"C\", version");
    if (!q.ok()) return q.status();
    const PGresult* r = q->get();
    for (int i = 0; i < PQntuples(r); ++i) {
      out.push_back({Text(r, i, 0), static_cast<int>(Int(r, i, 1)), Text(r, i, 2), Text(r, i, 3)});
    }
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::StatusOr<std::vector<AuditRow>> PostgresStore::AllAudit() {
  std::vector<AuditRow> out;
  auto st = WithConn([&](PGconn* c) -> absl::Status {
    auto q = Exec(c, "SELECT id, utc, identity, role, peer, request_id, rpc, serial, detail FROM audit ORDER BY id");
    if (!q.ok()) return q.status();
    const PGresult* r = q->get();
    for (int i = 0; i < PQntuples(r); ++i) {
      out.push_back({Int(r, i, 0), Text(r, i, 1), Text(r, i, 2), Text(r, i, 3), Text(r, i, 4), Text(r, i, 5),
                     Text(r, i, 6), Text(r, i, 7), Text(r, i, 8)});
    }
    return absl::OkStatus();
  });
  if (!st.ok()) return st;
  return out;
}

absl::Status PostgresStore::ImportTrail(const std::vector<ReleaseRow>& releases, const std::vector<AuditRow>& audit,
                                        const std::vector<ChainRow>& chain,
                                        const std::vector<ReleaseLinkRow>& release_chain) {
  return WithTransaction([&](PGconn* c) -> absl::Status {
    for (const auto& r : releases) {
      if (auto x = Exec(c, "INSERT INTO releases (serial, version, released_by, released_utc) VALUES ($1,$2,$3,$4)",
                        {T(r.serial), I(r.version), T(r.released_by), T(r.released_utc)});
          !x.ok()) {
        return x.status();
      }
    }
    for (const auto& a : audit) {
      if (auto x = Exec(c,
                        "INSERT INTO audit (id, utc, identity, role, peer, request_id, rpc, serial, detail) "
                        "VALUES ($1,$2,$3,$4,$5,$6,$7,$8,$9)",
                        {I(a.id), T(a.utc), T(a.identity), T(a.role), T(a.peer), T(a.request_id), T(a.rpc),
                         T(a.serial), T(a.detail)});
          !x.ok()) {
        return x.status();
      }
    }
    if (!audit.empty()) {
      // Later audit rows continue after the imported ids.
      if (auto x = Exec(c, "SELECT setval(pg_get_serial_sequence('audit', 'id'), (SELECT MAX(id) FROM audit))");
          !x.ok()) {
        return x.status();
      }
    }
    for (const auto& l : chain) {
      if (auto x = Exec(c,
                        "INSERT INTO calibration_chain (serial, version, prev_sha256, row_sha256) "
                        "VALUES ($1,$2,$3,$4)",
                        {T(l.serial), I(l.version), T(l.prev_sha256), T(l.row_sha256)});
          !x.ok()) {
        return x.status();
      }
    }
    for (const auto& l : release_chain) {
      if (auto x = Exec(c,
                        "INSERT INTO release_chain (seq, serial, version, calibration_sha256, prev_sha256, row_sha256) "
                        "VALUES ($1,$2,$3,$4,$5,$6)",
                        {I(l.seq), T(l.serial), I(l.version), T(l.calibration_sha256), T(l.prev_sha256),
                         T(l.row_sha256)});
          !x.ok()) {
        return x.status();
      }
    }
    return absl::OkStatus();
  });
}

}  // namespace fluxcal::storage
