#include "pipeline/anchor.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <map>

#include "absl/strings/str_cat.h"
#include "io/csv.h"
#include "nlohmann/json.hpp"

namespace fluxcal::pipeline {
namespace {

using nlohmann::json;

bool IsSha256Hex(const std::string& s) {
  if (s.size() != 64) return false;
  for (char c : s) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) return false;
  }
  return true;
}

}  // namespace

std::string AnchorLine(const storage::ChainHead& head, const std::string& kind, const std::string& backend,
                       const std::string& created_utc) {
  json j = {{"format", kAnchorFormat}, {"kind", kind}, {"created_utc", created_utc}, {"backend", backend}};
  json cals = json::array();
  for (const auto& c : head.calibrations) {
    cals.push_back({{"serial", c.serial}, {"version", c.version}, {"row_sha256", c.row_sha256}});
  }
  j["calibrations"] = std::move(cals);
  if (head.release_seq > 0) {
    j["release"] = {{"seq", head.release_seq}, {"serial", head.release_serial}, {"version", head.release_version},
                    {"row_sha256", head.release_sha256}};
  }
  if (!head.digest_sha256.empty()) j["digest_sha256"] = head.digest_sha256;
  return j.dump(-1, ' ', false, json::error_handler_t::replace);
}

absl::Status AppendAnchorLine(const std::string& path, const std::string& line) {
  const std::string text = line + "\n";
  const int fd = ::open(path.c_str(), O_WRONLY | O_APPEND | O_CREAT | O_CLOEXEC, 0644);
  if (fd < 0) {
    return absl::UnavailableError(absl::StrCat("anchor file '", path, "': cannot open: ", std::strerror(errno)));
  }
  size_t done = 0;
  while (done < text.size()) {
    const ssize_t n = ::write(fd, text.data() + done, text.size() - done);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      const int e = errno;
      ::close(fd);
      return absl::UnavailableError(absl::StrCat("anchor file '", path, "': cannot write: ", std::strerror(e)));
    }
    done += static_cast<size_t>(n);
  }
  const bool synced = ::fsync(fd) == 0;
  const int e = errno;
  ::close(fd);
  if (!synced) return absl::UnavailableError(absl::StrCat("anchor file '", path, "': fsync: ", std::strerror(e)));
  return absl::OkStatus();
}

absl::StatusOr<Anchor> ReadAnchorFile(const std::string& path) {
  if (!std::filesystem::exists(path)) {
    return absl::NotFoundError(absl::StrCat("anchor file '", path, "': does not exist"));
  }
  auto text = io::ReadFileToString(path);
  if (!text.ok()) return text.status();
  Anchor out;
  std::map<std::string, storage::ChainHead::Head> newest;
  size_t pos = 0;
  int line_no = 0;
  while (pos < text->size()) {
    const size_t end = text->find('\n', pos);
    const std::string line = text->substr(pos, end == std::string::npos ? std::string::npos : end - pos);
    pos = end == std::string::npos ? text->size() : end + 1;
    ++line_no;
    if (line.empty()) continue;
    auto bad = [&](const std::string& field, const std::string& why) {
      return absl::InvalidArgumentError(absl::StrCat(path, ":", line_no, ": field '", field, "': ", why));
    };
    const json j = json::parse(line, nullptr, false);
    if (j.is_discarded() || !j.is_object()) return bad("(line)", "not a JSON object");
    if (!j.contains("format") || j["format"] != kAnchorFormat) {
      return bad("format", absl::StrCat("expected \"", kAnchorFormat, "\""));
    }
    if (!j.contains("created_utc") || !j["created_utc"].is_string()) return bad("created_utc", "expected a string");
    if (!j.contains("calibrations") || !j["calibrations"].is_array()) return bad("calibrations", "expected an array");
    int k = 0;
    for (const auto& c : j["calibrations"]) {
      const std::string field = absl::StrCat("calibrations[", k++, "]");
      if (!c.is_object() || !c.contains("serial") || !c["serial"].is_string() || !c.contains("version") ||
          !c["version"].is_number_integer() || !c.contains("row_sha256") || !c["row_sha256"].is_string()) {
        return bad(field, "expected {\"serial\": string, \"version\": integer, \"row_sha256\": string}");
      }
      storage::ChainHead::Head h{c["serial"].get<std::string>(), c["version"].get<int>(),
                                 c["row_sha256"].get<std::string>()};
      if (h.version < 1) return bad(field + ".version", "expected >= 1");
      if (!IsSha256Hex(h.row_sha256)) return bad(field + ".row_sha256", "expected 64 lower-case hex digits");
      auto& n = newest[h.serial];
      if (h.version > n.version) n = std::move(h);
    }
    if (j.contains("release")) {
      const auto& r = j["release"];
      if (!r.is_object() || !r.contains("seq") || !r["seq"].is_number_integer() || !r.contains("serial") ||
          !r["serial"].is_string() || !r.contains("version") || !r["version"].is_number_integer() ||
          !r.contains("row_sha256") || !r["row_sha256"].is_string()) {
        return bad("release", "expected {\"seq\", \"serial\", \"version\", \"row_sha256\"}");
      }
      if (!IsSha256Hex(r["row_sha256"].get<std::string>())) {
        return bad("release.row_sha256", "expected 64 lower-case hex digits");
      }
      const int64_t seq = r["seq"].get<int64_t>();
      if (seq < 1) return bad("release.seq", "expected >= 1");
      if (seq > out.head.release_seq) {
        out.head.release_seq = seq;
        out.head.release_serial = r["serial"].get<std::string>();
        out.head.release_version = r["version"].get<int>();
        out.head.release_sha256 = r["row_sha256"].get<std::string>();
      }
    }
    ++out.lines;
    out.newest_utc = j["created_utc"].get<std::string>();
  }
  if (out.lines == 0) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": empty: no anchor line (fluxcal admin anchor --out)"));
  }
  for (auto& [serial, h] : newest) out.head.calibrations.push_back(std::move(h));
  return out;
}

absl::StatusOr<storage::ChainHead> AnchorStore(storage::Store& store, const std::string& out_path) {
  auto head = storage::CurrentChainHead(store);
  if (!head.ok()) return head.status();
  if (!out_path.empty()) {
    if (auto s = AppendAnchorLine(out_path, AnchorLine(*head, "snapshot", store.Backend(), storage::NowUtc()));
        !s.ok()) {
      return s;
    }
  }
  return head;
}

absl::Status AppendAnchorEvent(storage::Store& store, const std::string& path, const std::string& serial) {
  storage::ChainHead head;
  auto h = storage::SerialHead(store, serial);
  if (h.ok()) {
    head.calibrations.push_back(*h);
  } else if (h.status().code() != absl::StatusCode::kNotFound) {
    return h.status();
  }
  if (auto s = storage::SetNewestRelease(store, &head); !s.ok()) return s;
  return AppendAnchorLine(path, AnchorLine(head, "event", store.Backend(), storage::NowUtc()));
}

absl::StatusOr<storage::ChainReport> VerifyStore(storage::Store& store, const std::string& anchor_path) {
  if (anchor_path.empty()) return storage::VerifyChains(store);
  auto anchor = ReadAnchorFile(anchor_path);
  if (!anchor.ok()) return anchor.status();
  return storage::VerifyChains(store, &anchor->head,
                               absl::StrCat("the anchor in ", anchor_path, " (newest line ", anchor->newest_utc, ")"));
}

}  // namespace fluxcal::pipeline
