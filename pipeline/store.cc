#include "pipeline/store.h"

#include "storage/sqlite_store.h"

namespace fluxcal::pipeline {

absl::StatusOr<std::unique_ptr<storage::Store>> OpenStore(const std::string& url, bool create) {
  storage::Store::OpenOptions options;
  options.create = create;
  return storage::Store::Open(url, options);
}

absl::StatusOr<std::unique_ptr<storage::Store>> BackupSqliteStore(const std::string& path, const std::string& out) {
  auto store = storage::SqliteStore::Open(path, /*create=*/false);
  if (!store.ok()) return store.status();
  if (auto st = (*store)->Backup(out); !st.ok()) return st;
  return std::unique_ptr<storage::Store>(std::move(*store));
}

std::string StoreNowUtc() { return storage::NowUtc(); }

}  // namespace fluxcal::pipeline
