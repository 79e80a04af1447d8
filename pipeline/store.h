// The store as cli/ and server/ open it and hand it to the use cases. The
// Store interface and its rows (storage/store.h) are part of this layer's
// vocabulary: every stored use case takes a `storage::Store&` and returns
// its rows, so this header includes storage/store.h (and pipeline links
// fluxcal_storage PUBLIC) rather than wrapping each row in a copy.
#ifndef FLUXCAL_PIPELINE_STORE_H_
#define FLUXCAL_PIPELINE_STORE_H_

#include <memory>
#include <string>

#include "absl/status/statusor.h"
#include "storage/store.h"

namespace fluxcal::pipeline {

// storage::Store::Open: "postgresql://..." / "postgres://..." (PostgreSQL),
// "sqlite:PATH", a file path or ":memory:" (SQLite); pending migrations
// applied. `create` false: the store must exist (commands that only read).
absl::StatusOr<std::unique_ptr<storage::Store>> OpenStore(const std::string& url, bool create = true);

// `fluxcal admin backup`: an online copy of the SQLite store at `path` (which
// must exist) into `out`; returns the live store, opened without creating.
absl::StatusOr<std::unique_ptr<storage::Store>> BackupSqliteStore(const std::string& path, const std::string& out);

// Now as the store writes its timestamps (UTC, ISO 8601).
std::string StoreNowUtc();

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_STORE_H_
