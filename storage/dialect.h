// What differs between the databases a store runs on, as data: the
// migrations, and the few clauses the shared SQL in storage/sql_store.cc
// takes from here. Everything else (upserts with ON CONFLICT, RETURNING,
// the queries) is one text for both: SQLite >= 3.35 and PostgreSQL speak it.
#ifndef FLUXCAL_STORAGE_DIALECT_H_
#define FLUXCAL_STORAGE_DIALECT_H_

#include <string>
#include <vector>

namespace fluxcal::storage {

struct Dialect {
  std::string name;                      // "sqlite" | "postgresql" (Store::Backend, error prefixes)
  std::vector<std::string> migrations;   // index k: schema version k -> k + 1
  // The statement that starts a write transaction. SQLite's IMMEDIATE takes
  // the file's write lock first, so a version number read inside cannot
  // move, also across processes.
  std::string begin;
  // Row locks appended to a SELECT (PostgreSQL; SQLite's file lock already
  // serialises writers): FOR UPDATE orders version assignment per serial,
  // FOR SHARE concurrent releases of one version.
  std::string for_update, for_share;
  // Appended to ORDER BY serial so every backend orders bytewise, as SQLite
  // does by default (anchors and hashes list serials in that order).
  std::string bytewise;
  // A transaction-scoped lock taking one int64 parameter, serialising
  // migrations and appends to the one release chain across servers; ""
  // where the write transaction already does (SQLite).
  std::string advisory_lock;
  // One row with 1 when the table named by the parameter exists, else 0.
  std::string table_exists;
  // The v8 migration's one sanctioned rewrite of calibration versions: the
  // statements that lift and restore the trigger refusing UPDATE.
  std::string unlock_calibrations, relock_calibrations;
  // After rows were imported with their ids: identity columns continue
  // after them ("" where the database does so by itself).
  std::string after_import_runs, after_import_audit;
};

const Dialect& SqliteDialect();
const Dialect& PostgresDialect();

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_DIALECT_H_
