// The PostgreSQL backend of the storage seam (storage/sql_source.h), on
// libpq (Debian libpq-dev; compiled only when configure found it).
//
// Stateless servers share one database: nothing is cached between calls.
// A small pool of connections serves concurrent calls (a libpq connection
// is not thread-safe). Commits use the server's default
// synchronous_commit=on, so an acknowledgement means the commit is on disk.
#ifndef FLUXCAL_STORAGE_POSTGRES_SOURCE_H_
#define FLUXCAL_STORAGE_POSTGRES_SOURCE_H_

#include <memory>
#include <string>

#include "storage/sql_source.h"

namespace fluxcal::storage {

// `url`: a libpq connection URI ("postgresql://user@host:port/db"); a
// connect timeout of 5 s is added unless it names one. Connects lazily:
// the first call reports a database that does not answer (Unavailable).
absl::StatusOr<std::unique_ptr<SqlPool>> OpenPostgresPool(const std::string& url, int max_connections = 16);

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_POSTGRES_SOURCE_H_
