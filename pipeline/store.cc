#include "pipeline/store.h"

#include "pipeline/calibration_codec.h"
#include "storage/sql_store.h"
#include "storage/sqlite_source.h"

namespace fluxcal::pipeline {

absl::StatusOr<std::unique_ptr<storage::Store>> OpenStore(const std::string& url, bool create) {
  storage::Store::OpenOptions options;
  options.create = create;
  // The v8 migration converts stored JSON with the calibration codec.
  options.json_to_model = CalibrationJsonToModel;
  return storage::Store::Open(url, options);
}

absl::StatusOr<std::unique_ptr<storage::Store>> BackupSqliteStore(const std::string& path, const std::string& out) {
  auto pool = storage::OpenSqlitePool(path, /*create=*/false);
  if (!pool.ok()) return pool.status();
  auto store = storage::SqlStore::Open(std::move(*pool), /*create=*/false, CalibrationJsonToModel);
  if (!store.ok()) return store.status();
  if (auto st = (*store)->Backup(out); !st.ok()) return st;
  return std::unique_ptr<storage::Store>(std::move(*store));
}

std::string StoreNowUtc() { return storage::NowUtc(); }

}  // namespace fluxcal::pipeline
