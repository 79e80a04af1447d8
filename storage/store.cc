#include "storage/store.h"

#include <map>
#include <set>

#include <ctime>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/sha256.h"
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

std::string CalibrationRowSha256(const std::string& prev_sha256, const CalibrationRow& r) {
  std::string buf;
  auto put = [&](const std::string& field) { absl::StrAppend(&buf, field.size(), ":", field, ";"); };
  put(prev_sha256);
  put(r.serial);
  put(std::to_string(r.version));
  put(std::to_string(r.run_id));
  put(r.created_utc);
  put(r.model);
  put(absl::StrFormat("%.17g", r.psi_pm_wb));
  put(absl::StrFormat("%.17g", r.rms_relative));
  put(r.verdict);
  put(r.calibration_json);
  return io::Sha256Hex(buf);
}

absl::StatusOr<ChainReport> VerifyCalibrationChain(Store& store) {
  auto cals = store.AllCalibrations();
  if (!cals.ok()) return cals.status();
  auto links = store.AllChainRows();
  if (!links.ok()) return links.status();
  std::map<std::pair<std::string, int>, ChainRow> by_key;
  for (auto& l : *links) by_key[{l.serial, l.version}] = l;
  ChainReport rep;
  std::string serial, prev;
  bool chained_seen = false;
  std::set<std::pair<std::string, int>> present;
  for (const auto& c : *cals) {
    if (c.serial != serial) {
      serial = c.serial;
      prev.clear();
      chained_seen = false;
    }
    present.insert({c.serial, c.version});
    auto it = by_key.find({c.serial, c.version});
    if (it == by_key.end()) {
      if (chained_seen) {
        rep.problems.push_back(absl::StrCat(c.serial, " v", c.version, ": no chain link (row inserted around the store)"));
      } else {
        ++rep.unchained;
      }
      continue;
    }
    chained_seen = true;
    const ChainRow& l = it->second;
    if (l.prev_sha256 != prev) {
      rep.problems.push_back(absl::StrCat(c.serial, " v", c.version, ": chain broken (a version before it was changed or removed)"));
    }
    if (CalibrationRowSha256(l.prev_sha256, c) != l.row_sha256) {
      rep.problems.push_back(absl::StrCat(c.serial, " v", c.version, ": row changed after it was stored"));
    } else {
      ++rep.chained;
    }
    prev = l.row_sha256;
  }
  for (const auto& [key, l] : by_key) {
    if (!present.count(key)) {
      rep.problems.push_back(absl::StrCat(key.first, " v", key.second, ": calibration row removed"));
    }
  }
  return rep;
}

}  // namespace fluxcal::storage
