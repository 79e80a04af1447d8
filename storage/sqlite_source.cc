#include "storage/sqlite_source.h"

#include <map>
#include <mutex>

#include "absl/strings/str_cat.h"
#include "storage/dialect.h"
#include "storage/sqlite.h"

namespace fluxcal::storage {
namespace {

class SqliteSource final : public SqlSource {
 public:
  explicit SqliteSource(std::unique_ptr<Database> db) : db_(std::move(db)) {}
  const Dialect& dialect() const override { return SqliteDialect(); }

  absl::StatusOr<SqlRows> Query(std::string_view sql, const std::vector<SqlValue>& params) override {
    // Prepared once per text and kept: the store runs a few dozen texts,
    // many of them per row (points, imports).
    auto it = cache_.find(std::string(sql));
    if (it == cache_.end()) {
      auto st = db_->Prepare(sql);
      if (!st.ok()) return st.status();
      it = cache_.emplace(std::string(sql), std::make_unique<Statement>(std::move(*st))).first;
    }
    Statement& q = *it->second;
    absl::StatusOr<SqlRows> out = Run(q, params);
    (void)q.Reset();   // ends the statement: no read lock outlives the call
    return out;
  }
  absl::Status ExecScript(std::string_view sql) override { return db_->Exec(sql); }
  absl::Status Begin() override { return db_->Exec(dialect().begin); }
  absl::Status Commit() override { return db_->Exec("COMMIT"); }
  absl::Status Rollback() override { return db_->Exec("ROLLBACK"); }
  Database& db() { return *db_; }

 private:
  static absl::StatusOr<SqlRows> Run(Statement& q, const std::vector<SqlValue>& params) {
    if (auto st = q.BindAll(params); !st.ok()) return st;
    SqlRows rows;
    while (true) {
      auto r = q.Step();
      if (!r.ok()) return r.status();
      if (!*r) break;
      std::vector<SqlValue> cells(q.Columns());
      for (int c = 0; c < q.Columns(); ++c) cells[c] = q.Value(c);
      rows.emplace_back(std::move(cells));
    }
    return rows;
  }

  std::unique_ptr<Database> db_;
  // Declared after db_: the statements are finalized before the database closes.
  std::map<std::string, std::unique_ptr<Statement>> cache_;
};

class SqlitePool final : public SqlPool {
 public:
  explicit SqlitePool(std::unique_ptr<Database> db) : source_(std::move(db)) {}
  const Dialect& dialect() const override { return SqliteDialect(); }
  absl::Status WithSource(const std::function<absl::Status(SqlSource&)>& fn) override {
    std::lock_guard<std::mutex> lock(mu_);
    return fn(source_);
  }
  absl::Status BackupTo(const std::string& dest_path) override {
    std::lock_guard<std::mutex> lock(mu_);
    return source_.db().BackupTo(dest_path);
  }

 private:
  std::mutex mu_;
  SqliteSource source_;
};

}  // namespace

absl::StatusOr<std::unique_ptr<SqlPool>> OpenSqlitePool(const std::string& path, bool create) {
  // A read-only caller's path must already be a fluxcal store.
  auto db = Database::Open(path, create, create ? "" : "schema_version");
  if (!db.ok() && !create && db.status().code() == absl::StatusCode::kNotFound &&
      db.status().message().find("has no table") != std::string_view::npos) {
    return absl::NotFoundError(absl::StrCat("sqlite: '", path, "' holds no fluxcal store (no schema_version table)"));
  }
  if (!db.ok()) return db.status();
  return std::unique_ptr<SqlPool>(new SqlitePool(std::move(*db)));
}

}  // namespace fluxcal::storage
