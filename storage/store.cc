#include "storage/store.h"

#include <ctime>

#include "absl/strings/match.h"
#include "storage/postgres_store.h"
#include "storage/sqlite_store.h"

namespace fluxcal::storage {

std::string NowUtc() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::tm tm{};
  gmtime_r(&t, &tm);
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

absl::StatusOr<std::unique_ptr<Store>> Store::Open(const std::string& url) {
  if (absl::StartsWith(url, "postgresql://") || absl::StartsWith(url, "postgres://")) {
    auto s = PostgresStore::Open(url);
    if (!s.ok()) return s.status();
    return std::unique_ptr<Store>(std::move(*s));
  }
  const std::string path = absl::StartsWith(url, "sqlite:") ? url.substr(7) : url;
  auto s = SqliteStore::Open(path);
  if (!s.ok()) return s.status();
  return std::unique_ptr<Store>(std::move(*s));
}

}  // namespace fluxcal::storage
