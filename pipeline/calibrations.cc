// Stored calibrations read back: parsed (and cached by their chain hash),
// from a file or JSON, queried at an operating point, and their stored rows.
#include "pipeline/pipeline.h"

#include <map>
#include <memory>
#include <mutex>
#include <optional>

#include "absl/strings/str_cat.h"
#include "nlohmann/json.hpp"
#include "pipeline/calibration_codec.h"

namespace fluxcal::pipeline {

namespace {

// Parsed calibrations, by serial and version, keyed on the version's chain
// hash (storage::CalibrationRowSha256: SHA-256 over every stored field).
// Parsing dominated a query once calibrations carried a smoothing spline's
// covariance as ~0.5 MB of JSON (QueryFlux p50 went from 0.7 to 8 ms);
// since schema v8 a version is ~40 kB of binary that decodes in ~0.3 ms
// (docs/performance.md), and a hit still saves moving it out of the
// database: stored rows never change (append-only, hash-chained), so a hit
// needs only the tiny chain link. Rows from before the chain (schema < 6)
// are compared by their content instead. At most kCachedCalibrations entries, the least recently
// used evicted.
constexpr size_t kCachedCalibrations = 64;
struct CachedCalibration {
  std::string content;   // chain hash, or the JSON text for unchained rows
  std::shared_ptr<const fit::Calibration> cal;
  uint64_t last_use = 0;
};
std::mutex cache_mu;
std::map<std::pair<std::string, int>, CachedCalibration>& Cache() {
  static auto* c = new std::map<std::pair<std::string, int>, CachedCalibration>;
  return *c;
}
uint64_t cache_tick = 0;

std::optional<fit::Calibration> CacheLookup(const std::pair<std::string, int>& key, const std::string& content) {
  std::lock_guard<std::mutex> lock(cache_mu);
  auto it = Cache().find(key);
  if (it == Cache().end() || it->second.content != content) return std::nullopt;
  it->second.last_use = ++cache_tick;
  return *it->second.cal;
}

void CacheStore(const std::pair<std::string, int>& key, std::string content, const fit::Calibration& cal) {
  std::lock_guard<std::mutex> lock(cache_mu);
  auto& cache = Cache();
  if (cache.size() >= kCachedCalibrations && !cache.count(key)) {
    auto oldest = cache.begin();
    for (auto it = cache.begin(); it != cache.end(); ++it)
      if (it->second.last_use < oldest->second.last_use) oldest = it;
    cache.erase(oldest);
  }
  cache[key] = {std::move(content), std::make_shared<const fit::Calibration>(cal), ++cache_tick};
}

}  // namespace

absl::StatusOr<fit::Calibration> LoadCalibration(storage::Store& store, const std::string& serial, int version) {
  // The chain link names the version and its content hash without moving
  // the row; the prefix keeps two stores' hashes apart in one process.
  auto link = store.ChainLink(serial, version);
  if (link.ok()) {
    const std::string content = absl::StrCat(store.Backend(), ":", link->row_sha256);
    if (auto hit = CacheLookup({serial, link->version}, content)) return *hit;
  }
  auto row = store.GetCalibration(serial, version);
  if (!row.ok()) return row.status();
  const bool chained = link.ok() && link->version == row->version;
  const std::string content =
      chained ? absl::StrCat(store.Backend(), ":", link->row_sha256)
              : (row->model_pb.empty() ? row->calibration_json : row->model_pb);
  if (!chained) {
    if (auto hit = CacheLookup({serial, row->version}, content)) return *hit;
  }
  auto parsed = ParseStoredCalibration(*row);
  if (!parsed.ok()) return parsed.status();
  CacheStore({serial, row->version}, content, *parsed);
  return *parsed;
}

absl::StatusOr<fit::Calibration> LoadCalibrationFile(const std::string& path) { return fit::LoadCalibrationFile(path); }

absl::StatusOr<fit::Calibration> ParseCalibrationJson(const nlohmann::json& j) { return fit::Calibration::FromJson(j); }

const char* FluxRegionName(fit::Region region) { return fit::RegionName(region); }

absl::StatusOr<fit::Calibration> ParseStoredCalibration(const storage::CalibrationRow& stored) {
  if (!stored.model_pb.empty()) {
    auto cal = DecodeCalibration(stored.model_pb);
    if (!cal.ok()) {
      return absl::DataLossError(
          absl::StrCat("stored calibration of ", stored.serial, " is corrupt: ", cal.status().message()));
    }
    cal->version = stored.version;   // the version it is stored under
    return cal;
  }
  const storage::CalibrationRow* row = &stored;
  const std::string& serial = stored.serial;
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(row->calibration_json);
  } catch (const nlohmann::json::exception& e) {
    return absl::DataLossError(absl::StrCat("stored calibration of ", serial, " is corrupt: ", e.what()));
  }
  // The stored JSON carries the version it is stored under.
  j["version"] = row->version;
  return fit::Calibration::FromJson(j);
}

absl::StatusOr<QueryResult> QueryFlux(storage::Store& store, const std::string& serial, int version,
                                      const std::vector<std::pair<double, double>>& points) {
  auto cal = LoadCalibration(store, serial, version);
  if (!cal.ok()) return cal.status();
  QueryResult out;
  out.version = cal->version;
  out.values.reserve(points.size());
  for (const auto& [id, iq] : points) out.values.push_back(cal->Predict(id, iq));
  return out;
}

absl::StatusOr<storage::CalibrationRow> StoredRowView(storage::Store& store, const std::string& serial, int version) {
  auto row = store.GetCalibration(serial, version);
  if (!row.ok()) return row.status();
  auto text = StoredCalibrationJsonText(*row);
  if (!text.ok()) return text.status();
  row->calibration_json = std::move(*text);
  return row;
}

absl::StatusOr<storage::CalibrationRow> GetCalibrationRecord(storage::Store& store, const std::string& serial,
                                                             int version) {
  return StoredRowView(store, serial, version);
}

}  // namespace fluxcal::pipeline
