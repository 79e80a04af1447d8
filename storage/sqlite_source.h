// The SQLite backend of the storage seam (storage/sql_source.h): one file
// (or ":memory:") over storage/sqlite.h, WAL journal, synchronous=FULL, one
// connection guarded by a mutex (SQLite has one writer anyway; reads are
// short). Several processes may open the same file: BEGIN IMMEDIATE takes
// the file's write lock before a version number is read.
#ifndef FLUXCAL_STORAGE_SQLITE_SOURCE_H_
#define FLUXCAL_STORAGE_SQLITE_SOURCE_H_

#include <memory>
#include <string>

#include "storage/sql_source.h"

namespace fluxcal::storage {

// Opens the database at `path` (":memory:" too). `create` false: the file
// must exist and hold a fluxcal store (NotFound naming it otherwise, and
// nothing is created or written).
absl::StatusOr<std::unique_ptr<SqlPool>> OpenSqlitePool(const std::string& path, bool create);

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_SQLITE_SOURCE_H_
