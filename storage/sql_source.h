// The seam between the store and a database (after ml-metadata's
// MetadataSource): a backend only connects, runs SQL with bound parameters,
// begins, commits and rolls back. Everything a store means (versions,
// migrations, the hash chains, audit inside the write's transaction,
// idempotency) is written once above it, in storage/sql_store.cc, and the
// SQL that differs between databases is data in storage/dialect.h.
//
// Shared SQL is written with `?` placeholders, bound in order; a backend
// whose database spells them otherwise ($1, $2, ... on PostgreSQL) rewrites
// them. No value is ever spliced into SQL text.
//
// Errors (each backend maps its database's codes): AlreadyExists (a
// constraint), Unavailable (connection, busy), FailedPrecondition (a
// trigger refused the write, PostgreSQL), Aborted (serialisation, retry),
// Internal (anything else), each naming the statement.
#ifndef FLUXCAL_STORAGE_SQL_SOURCE_H_
#define FLUXCAL_STORAGE_SQL_SOURCE_H_

#include <cstdint>
#include <functional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace fluxcal::storage {

struct Dialect;

// One bound parameter or result cell.
using SqlValue = std::variant<std::nullptr_t, int64_t, double, std::string, std::vector<uint8_t>>;

// A text column as bytes, NULL when empty (model_pb: "" is "not stored").
SqlValue BytesOrNull(const std::string& bytes);
// NULL when empty (optional text columns: recording_sha256, idempotency_key).
SqlValue TextOrNull(const std::string& text);

// One result row. Accessors convert between the numeric and text forms a
// backend may return (PostgreSQL's text results, SQLite's dynamic types).
class SqlRow {
 public:
  explicit SqlRow(std::vector<SqlValue> cells) : cells_(std::move(cells)) {}
  bool IsNull(int col) const { return std::holds_alternative<std::nullptr_t>(cells_.at(col)); }
  int64_t Int(int col) const;
  int Int32(int col) const { return static_cast<int>(Int(col)); }
  double Double(int col) const;
  std::string Text(int col) const;              // bytes as they are; NULL ""
  std::vector<uint8_t> Blob(int col) const;     // NULL: empty

 private:
  std::vector<SqlValue> cells_;
};
using SqlRows = std::vector<SqlRow>;

// One connection. Not thread-safe: a SqlPool hands it to one caller at a time.
class SqlSource {
 public:
  virtual ~SqlSource() = default;
  virtual const Dialect& dialect() const = 0;
  // Runs one statement with `params` bound to its `?` in order; the rows
  // it returns (none for most writes; RETURNING returns them too).
  virtual absl::StatusOr<SqlRows> Query(std::string_view sql, const std::vector<SqlValue>& params = {}) = 0;
  // Runs constant SQL of one or more statements (DDL: the migrations).
  virtual absl::Status ExecScript(std::string_view sql) = 0;
  virtual absl::Status Begin() = 0;   // a write transaction (the dialect's begin)
  virtual absl::Status Commit() = 0;
  virtual absl::Status Rollback() = 0;
  // Inserts many rows into `table` inside the caller's transaction. This
  // one prepares one INSERT and runs it per row; a backend with a faster
  // path (PostgreSQL's COPY) overrides it.
  virtual absl::Status InsertRows(std::string_view table, const std::vector<std::string>& columns,
                                  const std::vector<std::vector<SqlValue>>& rows);

  // Query for a statement that returns at most one row: that row, or
  // NotFound with `not_found` as the message.
  absl::StatusOr<SqlRow> QueryOne(std::string_view sql, const std::vector<SqlValue>& params,
                                  const std::string& not_found);
  // Query for a statement returning no rows of interest.
  absl::Status Exec(std::string_view sql, const std::vector<SqlValue>& params = {});
};

// Connections for a store: a SQLite file has one (writes are serialised by
// the file anyway), PostgreSQL a small pool (stateless servers share one
// database). Thread-safe.
class SqlPool {
 public:
  virtual ~SqlPool() = default;
  virtual const Dialect& dialect() const = 0;
  // Runs fn on a connection held only by this caller for the call.
  virtual absl::Status WithSource(const std::function<absl::Status(SqlSource&)>& fn) = 0;
  // Online copy of the whole database into a new file (SQLite only;
  // Unimplemented elsewhere: PostgreSQL is backed up with pg_dump).
  virtual absl::Status BackupTo(const std::string& dest_path);
};

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_SQL_SOURCE_H_
