#include "storage/sqlite.h"

#include <sqlite3.h>

#include <filesystem>

#include "absl/strings/str_cat.h"

namespace fluxcal::storage {

namespace {
absl::Status SqlError(sqlite3* db, std::string_view what) {
  const int code = sqlite3_errcode(db);
  const std::string msg = absl::StrCat("sqlite: ", std::string(what), ": ", sqlite3_errmsg(db));
  if (code == SQLITE_CONSTRAINT) return absl::AlreadyExistsError(msg);
  if (code == SQLITE_BUSY || code == SQLITE_LOCKED) return absl::UnavailableError(msg);
  return absl::InternalError(msg);
}
}  // namespace

Statement::~Statement() {
  if (s_) sqlite3_finalize(s_);
}

absl::Status Statement::Bind(int i, const SqlValue& v) {
  int rc = SQLITE_OK;
  if (std::holds_alternative<std::nullptr_t>(v)) rc = sqlite3_bind_null(s_, i);
  else if (auto* x = std::get_if<int64_t>(&v)) rc = sqlite3_bind_int64(s_, i, *x);
  else if (auto* d = std::get_if<double>(&v)) rc = sqlite3_bind_double(s_, i, *d);
  else if (auto* t = std::get_if<std::string>(&v)) rc = sqlite3_bind_text(s_, i, t->data(), static_cast<int>(t->size()), SQLITE_TRANSIENT);
  else if (auto* b = std::get_if<std::vector<uint8_t>>(&v)) rc = sqlite3_bind_blob64(s_, i, b->data(), b->size(), SQLITE_TRANSIENT);
  return rc == SQLITE_OK ? absl::OkStatus() : SqlError(db_, "bind");
}

absl::Status Statement::BindAll(const std::vector<SqlValue>& values) {
  for (size_t k = 0; k < values.size(); ++k) {
    if (auto st = Bind(static_cast<int>(k + 1), values[k]); !st.ok()) return st;
  }
  return absl::OkStatus();
}

absl::StatusOr<bool> Statement::Step() {
  const int rc = sqlite3_step(s_);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  return SqlError(db_, sqlite3_sql(s_));
}

absl::Status Statement::Reset() {
  sqlite3_reset(s_);
  sqlite3_clear_bindings(s_);
  return absl::OkStatus();
}

int64_t Statement::Int(int c) const { return sqlite3_column_int64(s_, c); }
double Statement::Double(int c) const { return sqlite3_column_double(s_, c); }
bool Statement::IsNull(int c) const { return sqlite3_column_type(s_, c) == SQLITE_NULL; }
std::string Statement::Text(int c) const {
  const auto* p = sqlite3_column_text(s_, c);
  return p ? std::string(reinterpret_cast<const char*>(p), sqlite3_column_bytes(s_, c)) : std::string();
}
int Statement::Columns() const { return sqlite3_column_count(s_); }
SqlValue Statement::Value(int c) const {
  switch (sqlite3_column_type(s_, c)) {
    case SQLITE_NULL: return nullptr;
    case SQLITE_INTEGER: return Int(c);
    case SQLITE_FLOAT: return Double(c);
    case SQLITE_BLOB: return Blob(c);
    default: return Text(c);
  }
}
std::vector<uint8_t> Statement::Blob(int c) const {
  const auto* p = static_cast<const uint8_t*>(sqlite3_column_blob(s_, c));
  return p ? std::vector<uint8_t>(p, p + sqlite3_column_bytes(s_, c)) : std::vector<uint8_t>();
}

absl::StatusOr<std::unique_ptr<Database>> Database::Open(const std::string& path, bool create,
                                                         const std::string& required_table) {
  if (!create && path != ":memory:" && !std::filesystem::exists(path)) {
    return absl::NotFoundError(absl::StrCat("sqlite: no store at '", path, "': the file does not exist"));
  }
  sqlite3* db = nullptr;
  const int rc = sqlite3_open_v2(path.c_str(), &db,
                                 SQLITE_OPEN_READWRITE | (create ? SQLITE_OPEN_CREATE : 0) | SQLITE_OPEN_FULLMUTEX,
                                 nullptr);
  if (rc != SQLITE_OK) {
    const std::string msg = db ? sqlite3_errmsg(db) : "out of memory";
    if (db) sqlite3_close(db);
    return absl::UnavailableError(absl::StrCat("sqlite: cannot open '", path, "': ", msg));
  }
  std::unique_ptr<Database> d(new Database(db));
  sqlite3_busy_timeout(db, 5000);
  if (!required_table.empty()) {
    // A read only: a file that is not what the caller expects (an empty
    // file, another database) is left exactly as it was.
    auto q = d->Prepare("SELECT COUNT(*) FROM sqlite_master WHERE type = 'table' AND name = ?");
    if (!q.ok()) return absl::NotFoundError(absl::StrCat("sqlite: '", path, "': ", q.status().message()));
    if (auto b = q->Bind(1, required_table); !b.ok()) return b;
    auto r = q->Step();
    if (!r.ok()) return absl::NotFoundError(absl::StrCat("sqlite: '", path, "': ", r.status().message()));
    if (q->Int(0) == 0) {
      return absl::NotFoundError(absl::StrCat("sqlite: '", path, "' has no table '", required_table, "'"));
    }
  }
  for (const char* p : {"PRAGMA journal_mode=WAL", "PRAGMA synchronous=FULL", "PRAGMA foreign_keys=ON"}) {
    if (auto st = d->Exec(p); !st.ok()) return st;
  }
  return d;
}

Database::~Database() { sqlite3_close(db_); }

absl::StatusOr<Statement> Database::Prepare(std::string_view sql) {
  sqlite3_stmt* s = nullptr;
  if (sqlite3_prepare_v2(db_, sql.data(), static_cast<int>(sql.size()), &s, nullptr) != SQLITE_OK) {
    return SqlError(db_, absl::StrCat("prepare '", std::string(sql), "'"));
  }
  return Statement(db_, s);
}

absl::Status Database::Exec(std::string_view sql) {
  char* err = nullptr;
  const std::string s(sql);
  if (sqlite3_exec(db_, s.c_str(), nullptr, nullptr, &err) != SQLITE_OK) {
    const std::string msg = err ? err : "error";
    sqlite3_free(err);
    return absl::InternalError(absl::StrCat("sqlite: ", s.substr(0, 60), ": ", msg));
  }
  return absl::OkStatus();
}

absl::Status Database::Transaction(const std::function<absl::Status()>& fn) {
  if (auto st = Exec("BEGIN IMMEDIATE"); !st.ok()) return st;
  absl::Status st = fn();
  if (!st.ok()) {
    (void)Exec("ROLLBACK");
    return st;
  }
  if (auto c = Exec("COMMIT"); !c.ok()) {
    (void)Exec("ROLLBACK");
    return c;
  }
  return absl::OkStatus();
}

int64_t Database::LastInsertRowId() const { return sqlite3_last_insert_rowid(db_); }

absl::Status Database::BackupTo(const std::string& dest_path) {
  sqlite3* dest = nullptr;
  if (sqlite3_open_v2(dest_path.c_str(), &dest, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE, nullptr) != SQLITE_OK) {
    const std::string msg = dest ? sqlite3_errmsg(dest) : "out of memory";
    if (dest) sqlite3_close(dest);
    return absl::UnavailableError(absl::StrCat("sqlite: cannot create backup '", dest_path, "': ", msg));
  }
  sqlite3_backup* b = sqlite3_backup_init(dest, "main", db_, "main");
  if (!b) {
    const std::string msg = sqlite3_errmsg(dest);
    sqlite3_close(dest);
    return absl::InternalError(absl::StrCat("sqlite: backup to '", dest_path, "': ", msg));
  }
  // Whole database in one step: the copy is one consistent snapshot.
  const int rc = sqlite3_backup_step(b, -1);
  sqlite3_backup_finish(b);
  const int rc2 = sqlite3_errcode(dest);
  const std::string msg = sqlite3_errmsg(dest);
  sqlite3_close(dest);
  if (rc != SQLITE_DONE || rc2 != SQLITE_OK) {
    return absl::InternalError(absl::StrCat("sqlite: backup to '", dest_path, "' failed: ", msg));
  }
  return absl::OkStatus();
}

}  // namespace fluxcal::storage
