// RAII wrappers for sqlite3 and sqlite3_stmt: bound parameters only (never
// SQL built from values), errors as absl::Status naming the statement, and a
// Transaction(fn) that commits on OK and rolls back otherwise.
#ifndef FLUXCAL_STORAGE_SQLITE_H_
#define FLUXCAL_STORAGE_SQLITE_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "storage/sql_source.h"

struct sqlite3;
struct sqlite3_stmt;

namespace fluxcal::storage {

class Statement {
 public:
  Statement(sqlite3* db, sqlite3_stmt* s) : db_(db), s_(s) {}
  ~Statement();
  Statement(Statement&& o) noexcept : db_(o.db_), s_(o.s_) { o.s_ = nullptr; }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;

  absl::Status Bind(int index, const SqlValue& v);   // 1-based
  absl::Status BindAll(const std::vector<SqlValue>& values);
  // Steps once: true when a row is available, false when done.
  absl::StatusOr<bool> Step();
  absl::Status Reset();
  int64_t Int(int col) const;
  double Double(int col) const;
  bool IsNull(int col) const;
  std::string Text(int col) const;
  std::vector<uint8_t> Blob(int col) const;
  int Columns() const;
  SqlValue Value(int col) const;   // the cell as its stored type

 private:
  sqlite3* db_;
  sqlite3_stmt* s_;
};

class Database {
 public:
  // Opens (creating, unless `create` is false) a database file or
  // ":memory:". WAL journal, synchronous=FULL (a commit is durable when it
  // returns), foreign keys on, a bounded busy timeout. Without `create` a
  // path that does not exist is NotFound and no file is made; a non-empty
  // `required_table` must exist (NotFound otherwise), checked before
  // anything is written to the file.
  static absl::StatusOr<std::unique_ptr<Database>> Open(const std::string& path, bool create = true,
                                                        const std::string& required_table = "");
  ~Database();

  absl::StatusOr<Statement> Prepare(std::string_view sql);
  absl::Status Exec(std::string_view sql);   // constant SQL only (DDL, pragmas)
  // Runs fn inside BEGIN IMMEDIATE ... COMMIT; rolls back when fn fails.
  absl::Status Transaction(const std::function<absl::Status()>& fn);
  int64_t LastInsertRowId() const;
  // Online backup (sqlite3_backup_*) of the main database into a new file.
  absl::Status BackupTo(const std::string& dest_path);
  sqlite3* raw() const { return db_; }

 private:
  explicit Database(sqlite3* db) : db_(db) {}
  sqlite3* db_;
};

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_SQLITE_H_
