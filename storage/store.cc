#include "storage/store.h"

#include <algorithm>
#include <map>
#include <set>

#include <ctime>

#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/sha256.h"
#include "storage/sql_store.h"
#include "storage/sqlite_source.h"
#ifdef FLUXCAL_WITH_POSTGRESQL
#include "storage/postgres_source.h"
#endif

namespace fluxcal::storage {

std::string NowUtc() {
  const std::time_t t = std::time(nullptr);
  char buf[32];
  std::tm tm{};
  gmtime_r(&t, &tm);
  std::strftime(buf, sizeof buf, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

absl::StatusOr<std::unique_ptr<Store>> Store::Open(const std::string& url, const OpenOptions& options) {
  if (absl::StartsWith(url, "postgresql://") || absl::StartsWith(url, "postgres://")) {
#ifdef FLUXCAL_WITH_POSTGRESQL
    auto pool = OpenPostgresPool(url, 16);
    if (!pool.ok()) return pool.status();
    auto s = SqlStore::Open(std::move(*pool), options.create, options.json_to_model);
    if (!s.ok()) return s.status();
    return std::unique_ptr<Store>(std::move(*s));
#else
    return absl::UnimplementedError(
        "postgresql: this fluxcal was built without PostgreSQL support (libpq was not found at configure); "
        "use a SQLite store, or rebuild with libpq-dev installed");
#endif
  }
  const std::string path = absl::StartsWith(url, "sqlite:") ? url.substr(7) : url;
  auto pool = OpenSqlitePool(path, options.create);
  if (!pool.ok()) return pool.status();
  auto s = SqlStore::Open(std::move(*pool), options.create, options.json_to_model);
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
  if (!r.model_pb.empty()) put(r.model_pb);
  return io::Sha256Hex(buf);
}

std::string ConversionRowSha256(const std::string& link_row_sha256, const ConversionRow& x,
                                const CalibrationRow& converted) {
  // The link it was converted under, what the JSON was and when, as the
  // "previous hash" of the converted row's own hash: the same framing.
  std::string buf;
  auto put = [&](const std::string& field) { absl::StrAppend(&buf, field.size(), ":", field, ";"); };
  put(link_row_sha256);
  put(x.json_sha256);
  put(x.converted_utc);
  return CalibrationRowSha256(io::Sha256Hex(buf), converted);
}

std::optional<ConvertedVersion> ConvertStoredJson(const CalibrationRow& row, const ChainRow* link,
                                                  const JsonToModelFn& to_model, const std::string& now_utc) {
  if (!to_model || link == nullptr || row.calibration_json.empty() || !row.model_pb.empty()) return std::nullopt;
  if (CalibrationRowSha256(link->prev_sha256, row) != link->row_sha256) return std::nullopt;
  auto model = to_model(row.calibration_json);
  if (!model.ok() || model->empty()) return std::nullopt;
  ConvertedVersion out;
  out.row = row;
  out.row.calibration_json.clear();
  out.row.model_pb = std::move(*model);
  out.record = {row.serial, row.version, io::Sha256Hex(row.calibration_json), "", now_utc};
  out.record.row_sha256 = ConversionRowSha256(link->row_sha256, out.record, out.row);
  return out;
}

std::string ConversionAuditDetail(int converted, int versions, const std::string& records) {
  return absl::StrCat("schema v8: ", converted, " of ", versions,
                      " calibration versions converted from JSON to the binary model (calibration_conversions; the "
                      "others stay JSON and verify as before); records sha256 ",
                      io::Sha256Hex(records));
}

std::string VersionSha256(const CalibrationRow& row, const ChainRow* link) {
  return link != nullptr ? link->row_sha256 : CalibrationRowSha256("", row);
}

std::string ReleaseRowSha256(const std::string& prev_sha256, int64_t seq, const ReleaseRow& r,
                             const std::string& calibration_sha256) {
  // The same length-prefixed framing as CalibrationRowSha256: no field can
  // run into the next.
  std::string buf;
  auto put = [&](const std::string& field) { absl::StrAppend(&buf, field.size(), ":", field, ";"); };
  put(prev_sha256);
  put(std::to_string(seq));
  put(r.serial);
  put(std::to_string(r.version));
  put(r.released_by);
  put(r.released_utc);
  put(calibration_sha256);
  return io::Sha256Hex(buf);
}

std::string ChainHeadDigest(const ChainHead& h) {
  std::string buf;
  for (const auto& c : h.calibrations) absl::StrAppend(&buf, c.serial, "\t", c.version, "\t", c.row_sha256, "\n");
  absl::StrAppend(&buf, "release\t", h.release_seq, "\t", h.release_serial, "\t", h.release_version, "\t",
                  h.release_sha256, "\n");
  return io::Sha256Hex(buf);
}

absl::StatusOr<ChainHead::Head> SerialHead(Store& store, const std::string& serial) {
  auto link = store.ChainLink(serial, 0);
  if (!link.ok()) return link.status();
  return ChainHead::Head{serial, link->version, link->row_sha256};
}

absl::Status SetNewestRelease(Store& store, ChainHead* head) {
  auto rel = store.ReleaseLinkAt(0);
  if (rel.ok()) {
    head->release_seq = rel->seq;
    head->release_serial = rel->serial;
    head->release_version = rel->version;
    head->release_sha256 = rel->row_sha256;
  } else if (rel.status().code() != absl::StatusCode::kNotFound) {
    return rel.status();
  }
  return absl::OkStatus();
}

absl::StatusOr<ChainHead> CurrentChainHead(Store& store) {
  // From the links alone (small rows): the newest chained version of every
  // serial. Versions from before the chain (schema < 6) have no link and
  // are not anchored.
  auto links = store.AllChainRows();
  if (!links.ok()) return links.status();
  std::map<std::string, ChainHead::Head> newest;
  for (const auto& l : *links) {
    auto& h = newest[l.serial];
    if (l.version > h.version) h = {l.serial, l.version, l.row_sha256};
  }
  ChainHead out;
  for (auto& [serial, h] : newest) out.calibrations.push_back(std::move(h));
  if (auto s = SetNewestRelease(store, &out); !s.ok()) return s;
  out.digest_sha256 = ChainHeadDigest(out);
  return out;
}

namespace {

// The words of every chain problem, written once for VerifyChains (the
// whole store) and VerifyReleasedVersion (one version at export time).
std::string Cal(const std::string& serial, int version) { return absl::StrCat(serial, " v", version); }
std::string Rel(const ReleaseLinkRow& l) { return absl::StrCat(l.serial, " v", l.version, " (release #", l.seq, ")"); }
constexpr char kRowChanged[] = ": row changed after it was stored";
constexpr char kCalChainBroken[] = ": chain broken (a version before it was changed or removed)";
constexpr char kCalUnlinked[] = ": no chain link (row inserted around the store)";
constexpr char kReleaseUnlinked[] = ": release without a chain link (inserted around the service)";
constexpr char kReleaseChanged[] = ": release changed after it was stored";
constexpr char kReleaseChainBroken[] = ": release chain broken (a release before it was changed or removed)";
constexpr char kReleasedCalChanged[] = ": the released calibration version changed after its release";
constexpr char kConvertedChanged[] = ": row changed after the v8 migration converted it to binary";

// A converted version (ConversionRow) checks when the row is binary and the
// record's hash (ConversionRowSha256) recomputes.
bool ConversionVerifies(const ConversionRow& x, const ChainRow& link, const CalibrationRow& row) {
  return !row.model_pb.empty() && row.calibration_json.empty() &&
         ConversionRowSha256(link.row_sha256, x, row) == x.row_sha256;
}

std::string NotPass(const std::string& verdict) {
  return absl::StrCat(": released with verdict '", verdict, "' (only 'pass' is ever released by the service)");
}

}  // namespace

absl::StatusOr<ChainReport> VerifyChains(Store& store, const ChainHead* anchor, const std::string& anchor_name) {
  auto cals = store.AllCalibrations();
  if (!cals.ok()) return cals.status();
  auto links = store.AllChainRows();
  if (!links.ok()) return links.status();
  std::map<std::pair<std::string, int>, ChainRow> by_key;
  for (auto& l : *links) by_key[{l.serial, l.version}] = l;
  auto conversions = store.AllConversions();
  if (!conversions.ok()) return conversions.status();
  std::map<std::pair<std::string, int>, ConversionRow> converted;
  for (auto& x : *conversions) converted[{x.serial, x.version}] = x;
  ChainReport rep;
  std::string serial, prev;
  bool chained_seen = false;
  // Every stored version: its VersionSha256 and verdict; and each serial's
  // newest stored version.
  std::map<std::pair<std::string, int>, std::pair<std::string, std::string>> stored;
  std::map<std::string, int> newest;
  for (const auto& c : *cals) {
    if (c.serial != serial) {
      serial = c.serial;
      prev.clear();
      chained_seen = false;
    }
    newest[c.serial] = std::max(newest[c.serial], c.version);
    auto it = by_key.find({c.serial, c.version});
    stored[{c.serial, c.version}] = {VersionSha256(c, it == by_key.end() ? nullptr : &it->second), c.verdict};
    if (it == by_key.end()) {
      if (chained_seen) {
        rep.problems.push_back(Cal(c.serial, c.version) + kCalUnlinked);
      } else {
        ++rep.unchained;
      }
      continue;
    }
    chained_seen = true;
    const ChainRow& l = it->second;
    if (l.prev_sha256 != prev) rep.problems.push_back(Cal(c.serial, c.version) + kCalChainBroken);
    if (auto x = converted.find({c.serial, c.version}); x != converted.end()) {
      if (!ConversionVerifies(x->second, l, c)) {
        rep.problems.push_back(Cal(c.serial, c.version) + kConvertedChanged);
      } else {
        ++rep.chained;
        ++rep.converted;
      }
    } else if (CalibrationRowSha256(l.prev_sha256, c) != l.row_sha256) {
      rep.problems.push_back(Cal(c.serial, c.version) + kRowChanged);
    } else {
      ++rep.chained;
    }
    prev = l.row_sha256;
  }
  for (const auto& [key, l] : by_key) {
    if (!stored.count(key)) rep.problems.push_back(Cal(key.first, key.second) + ": calibration row removed");
  }

  // Releases: one chain in release order.
  auto releases = store.AllReleases();
  if (!releases.ok()) return releases.status();
  auto rlinks = store.AllReleaseLinks();
  if (!rlinks.ok()) return rlinks.status();
  std::map<std::pair<std::string, int>, ReleaseRow> release_by_key;
  for (const auto& r : *releases) release_by_key[{r.serial, r.version}] = r;
  std::set<std::pair<std::string, int>> linked;
  std::string rprev;
  int64_t expected_seq = 1;
  for (const auto& l : *rlinks) {
    const std::pair<std::string, int> key{l.serial, l.version};
    bool ok = true;
    // A problem of this link: reported, and the link not counted as chained.
    auto problem = [&](const std::string& what) {
      rep.problems.push_back(Rel(l) + what);
      ok = false;
    };
    if (l.seq != expected_seq) {
      for (int64_t k = expected_seq; k < l.seq; ++k) {
        rep.problems.push_back(absl::StrCat("release #", k, ": chain link removed"));
      }
      ok = false;
    } else if (l.prev_sha256 != rprev) {
      problem(kReleaseChainBroken);
    }
    auto it = release_by_key.find(key);
    if (it == release_by_key.end()) {
      problem(": release row removed");
    } else {
      linked.insert(key);
      if (ReleaseRowSha256(l.prev_sha256, l.seq, it->second, l.calibration_sha256) != l.row_sha256) {
        problem(kReleaseChanged);
      }
      auto cal = stored.find(key);
      if (cal == stored.end()) {
        problem(": the released calibration version is gone");
      } else {
        if (cal->second.first != l.calibration_sha256) problem(kReleasedCalChanged);
        if (cal->second.second != "pass") problem(NotPass(cal->second.second));
      }
    }
    if (ok) ++rep.releases_chained;
    rprev = l.row_sha256;
    expected_seq = l.seq + 1;
  }
  for (const auto& [key, r] : release_by_key) {
    if (linked.count(key)) continue;
    rep.problems.push_back(Cal(key.first, key.second) + kReleaseUnlinked);
    auto cal = stored.find(key);
    if (cal != stored.end() && cal->second.second != "pass") {
      rep.problems.push_back(Cal(key.first, key.second) + NotPass(cal->second.second));
    }
  }

  if (anchor != nullptr) {
    for (const auto& h : anchor->calibrations) {
      auto it = stored.find({h.serial, h.version});
      if (it == stored.end()) {
        if (by_key.count({h.serial, h.version})) continue;   // row removed, link kept: reported above
        auto n = newest.find(h.serial);
        rep.problems.push_back(absl::StrCat(
            Cal(h.serial, h.version), ": removed after ", anchor_name, " (row and chain link; the newest stored is ",
            n == newest.end() ? std::string("none") : absl::StrCat("v", n->second), ")"));
      } else if (it->second.first != h.row_sha256) {
        rep.problems.push_back(absl::StrCat(Cal(h.serial, h.version), ": differs from ", anchor_name));
      } else {
        ++rep.anchored;
      }
    }
    if (anchor->release_seq > 0) {
      const ReleaseLinkRow* at = nullptr;
      for (const auto& l : *rlinks) {
        if (l.seq == anchor->release_seq) at = &l;
      }
      const std::string what = absl::StrCat(anchor->release_serial, " v", anchor->release_version, " (release #",
                                            anchor->release_seq, ")");
      if (at == nullptr) {
        rep.problems.push_back(absl::StrCat(what, ": removed after ", anchor_name, " (release chain link)"));
      } else if (at->row_sha256 != anchor->release_sha256) {
        rep.problems.push_back(absl::StrCat(what, ": differs from ", anchor_name));
      } else {
        ++rep.anchored;
      }
    }
  }
  return rep;
}

absl::Status VerifyReleasedVersion(Store& store, const std::string& serial, int version) {
  auto release = store.GetRelease(serial, version);
  if (!release.ok()) {
    if (release.status().code() != absl::StatusCode::kNotFound) return release.status();
    return absl::FailedPreconditionError(
        absl::StrCat("version ", version, " of '", serial, "' is not released for flashing"));
  }
  const std::string what = Cal(serial, version);
  auto data_loss = [&](const std::string& why) {
    return absl::DataLossError(absl::StrCat(what, why, "; refusing to export it for flashing (fluxcal admin verify-db)"));
  };
  auto row = store.GetCalibration(serial, version);
  if (!row.ok()) {
    if (row.status().code() != absl::StatusCode::kNotFound) return row.status();
    return data_loss(": released, but the calibration row is gone");
  }
  // The calibration link: the row as stored, linked to the version before.
  auto link = store.ChainLink(serial, version);
  if (!link.ok() && link.status().code() != absl::StatusCode::kNotFound) return link.status();
  if (link.ok()) {
    auto conversion = store.Conversion(serial, version);
    if (!conversion.ok()) return conversion.status();
    if (conversion->has_value()) {
      if (!ConversionVerifies(**conversion, *link, *row)) return data_loss(kConvertedChanged);
    } else if (CalibrationRowSha256(link->prev_sha256, *row) != link->row_sha256) {
      return data_loss(kRowChanged);
    }
    auto before = version > 1 ? store.ChainLink(serial, version - 1) : absl::NotFoundError("first version");
    if (!before.ok() && before.status().code() != absl::StatusCode::kNotFound) return before.status();
    if (link->prev_sha256 != (before.ok() ? before->row_sha256 : std::string())) return data_loss(kCalChainBroken);
  } else {
    // No link: only a version stored before the chain existed, i.e. older
    // than every chained version of the serial.
    auto before = version > 1 ? store.ChainLink(serial, version - 1) : absl::NotFoundError("first version");
    if (!before.ok() && before.status().code() != absl::StatusCode::kNotFound) return before.status();
    auto newest = store.ChainLink(serial, 0);
    if (!newest.ok() && newest.status().code() != absl::StatusCode::kNotFound) return newest.status();
    if (before.ok() || (newest.ok() && newest->version < version)) return data_loss(kCalUnlinked);
  }
  // The release link: the release as stored, naming this very row, linked
  // to the release before.
  auto rl = store.ReleaseLink(serial, version);
  if (!rl.ok()) {
    if (rl.status().code() != absl::StatusCode::kNotFound) return rl.status();
    return data_loss(kReleaseUnlinked);
  }
  if (ReleaseRowSha256(rl->prev_sha256, rl->seq, *release, rl->calibration_sha256) != rl->row_sha256) {
    return data_loss(kReleaseChanged);
  }
  if (rl->calibration_sha256 != VersionSha256(*row, link.ok() ? &*link : nullptr)) return data_loss(kReleasedCalChanged);
  std::string prev;
  if (rl->seq > 1) {
    auto before = store.ReleaseLinkAt(rl->seq - 1);
    if (!before.ok() && before.status().code() != absl::StatusCode::kNotFound) return before.status();
    if (!before.ok()) return data_loss(absl::StrCat(": release chain broken (release #", rl->seq - 1, " removed)"));
    prev = before->row_sha256;
  }
  if (rl->prev_sha256 != prev) return data_loss(kReleaseChainBroken);
  // Only the service releases, and only a passing version: a release of
  // anything else was not made through it.
  if (row->verdict != "pass") {
    return absl::FailedPreconditionError(absl::StrCat(
        "version ", version, " of '", serial, "' has verdict '", row->verdict,
        "' (only 'pass' can be released; this release was not made by the service): not exported for flashing"));
  }
  return absl::OkStatus();
}

}  // namespace fluxcal::storage
