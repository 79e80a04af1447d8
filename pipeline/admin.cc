// Whole-store operations: a content hash over everything stored, and
// migrating every row from one store to another.
#include "pipeline/pipeline.h"

#include <optional>
#include <set>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/sha256.h"

namespace fluxcal::pipeline {
namespace {

// The lines of one store listing in the dump: `line` writes a row's
// fields, a newline ends each; a listing that failed is the hash's error.
template <typename Rows, typename Line>
absl::Status AppendLines(const absl::StatusOr<Rows>& rows, std::string* dump, Line line) {
  if (!rows.ok()) return rows.status();
  for (const auto& row : *rows) {
    line(row);
    *dump += "\n";
  }
  return absl::OkStatus();
}

// Copies every row of a listing of the source store with `import`, one by
// one, counting them into *count; the first error stops the copy.
template <typename Rows, typename Import>
absl::Status ImportEach(const absl::StatusOr<Rows>& rows, Import import, int* count) {
  if (!rows.ok()) return rows.status();
  for (const auto& row : *rows) {
    if (auto s = import(row); !s.ok()) return s;
    ++*count;
  }
  return absl::OkStatus();
}

}  // namespace

absl::StatusOr<std::string> ContentHash(storage::Store& store) {
  std::string dump;
  auto d = [&](double v) { absl::StrAppendFormat(&dump, "%.17g\t", v); };
  auto motors = store.AllMotors();
  if (!motors.ok()) return motors.status();
  for (const auto& m : *motors) {
    absl::StrAppend(&dump, "motor\t", m.serial, "\t", m.pole_pairs, "\t");
    d(m.rs_ohm); d(m.psi_pm_wb);
    absl::StrAppend(&dump, m.created_utc, "\n");
  }
  auto runs = store.AllRuns();
  if (!runs.ok()) return runs.status();
  for (const auto& r : *runs) {
    absl::StrAppend(&dump, "run\t", r.run_id, "\t", r.serial, "\t", r.station, "\t", r.kind, "\t", r.recording_sha256,
                    "\t", r.created_utc, "\t", r.idempotency_key, "\n");
    if (!r.recording_sha256.empty()) {
      auto rec = store.GetRecordingRow(r.recording_sha256);
      if (!rec.ok()) return rec.status();
      const std::string_view z(reinterpret_cast<const char*>(rec->zlib_data.data()), rec->zlib_data.size());
      absl::StrAppend(&dump, "recording\t", rec->size_bytes, "\t", io::Sha256Hex(z), "\n");
    }
    auto pts = store.RunPoints(r.run_id);
    if (!pts.ok()) return pts.status();
    for (const auto& p : *pts) {
      absl::StrAppend(&dump, "point\t", p.point_id, "\t");
      for (double v : {p.id_a, p.iq_a, p.speed_rpm, p.ld_h, p.lq_h}) d(v);
      if (p.ldq_h) d(*p.ldq_h); else dump += "null\t";
      for (double v : {p.ld_h_std, p.lq_h_std, p.ldq_h_std, p.temperature_c}) d(v);
      absl::StrAppend(&dump, p.reliable ? 1 : 0);
      // As the digest: only where stated (a dump of points without it is
      // as before).
      if (p.hf_flux_radius_wb) {
        dump += "\t";
        d(*p.hf_flux_radius_wb);
      }
      dump += "\n";
    }
  }
  auto cals = store.AllCalibrations();
  if (!cals.ok()) return cals.status();
  for (const auto& c : *cals) {
    absl::StrAppend(&dump, "calibration\t", c.serial, "\t", c.version, "\t", c.run_id, "\t", c.created_utc, "\t",
                    c.model, "\t");
    d(c.psi_pm_wb); d(c.rms_relative);
    // The content as stored: the binary model, or the JSON of a version
    // the v8 migration left as JSON.
    absl::StrAppend(&dump, c.verdict, "\t", io::Sha256Hex(c.calibration_json), "\t", io::Sha256Hex(c.model_pb), "\n");
  }
  // Text fields are length-prefixed: free text (audit detail) may hold tabs.
  auto t = [&](const std::string& v) { absl::StrAppend(&dump, v.size(), ":", v, "\t"); };
  // A row's serial and version, as every chained table keys them.
  auto sv = [&](const std::string& serial, int version) {
    t(serial);
    absl::StrAppend(&dump, version, "\t");
  };
  absl::Status st = AppendLines(store.AllReleases(), &dump, [&](const auto& r) {
    dump += "release\t";
    sv(r.serial, r.version); t(r.released_by); t(r.released_utc);
  });
  if (!st.ok()) return st;
  st = AppendLines(store.AllAudit(), &dump, [&](const auto& a) {
    absl::StrAppend(&dump, "audit\t", a.id, "\t");
    for (const auto* v : {&a.utc, &a.identity, &a.role, &a.peer, &a.request_id, &a.rpc, &a.serial, &a.detail}) t(*v);
  });
  if (!st.ok()) return st;
  st = AppendLines(store.AllChainRows(), &dump, [&](const auto& l) {
    dump += "link\t";
    sv(l.serial, l.version); t(l.prev_sha256); t(l.row_sha256);
  });
  if (!st.ok()) return st;
  st = AppendLines(store.AllReleaseLinks(), &dump, [&](const auto& l) {
    absl::StrAppend(&dump, "release_link\t", l.seq, "\t");
    sv(l.serial, l.version); t(l.calibration_sha256); t(l.prev_sha256); t(l.row_sha256);
  });
  if (!st.ok()) return st;
  return io::Sha256Hex(dump);
}

absl::StatusOr<MigrateResult> Migrate(storage::Store& from, storage::Store& to) {
  if (auto m = to.AllMotors(); !m.ok()) {
    return m.status();
  } else if (!m->empty()) {
    return absl::FailedPreconditionError("migrate: the target store is not empty");
  }
  MigrateResult out;
  if (auto s = ImportEach(from.AllMotors(), [&](const auto& m) { return to.ImportMotor(m); }, &out.motors); !s.ok()) {
    return s;
  }
  auto runs = from.AllRuns();
  if (!runs.ok()) return runs.status();
  std::set<std::string> recordings;
  for (const auto& r : *runs) {
    auto pts = from.RunPoints(r.run_id);
    if (!pts.ok()) return pts.status();
    std::optional<storage::RecordingRow> rec;
    if (!r.recording_sha256.empty() && recordings.insert(r.recording_sha256).second) {
      auto x = from.GetRecordingRow(r.recording_sha256);
      if (!x.ok()) return x.status();
      rec = std::move(*x);
      ++out.recordings;
    }
    if (auto s = to.ImportRun(r, *pts, rec ? &*rec : nullptr); !s.ok()) return s;
    ++out.runs;
    out.points += static_cast<int>(pts->size());
  }
  if (auto s = ImportEach(from.AllCalibrations(), [&](const auto& c) { return to.ImportCalibration(c); },
                          &out.calibrations);
      !s.ok()) {
    return s;
  }
  // Releases, the audit trail and the chain links as stored (ids, times and
  // hashes kept): the copy verifies as the source did.
  auto releases = from.AllReleases();
  if (!releases.ok()) return releases.status();
  auto audit = from.AllAudit();
  if (!audit.ok()) return audit.status();
  auto chain = from.AllChainRows();
  if (!chain.ok()) return chain.status();
  auto release_chain = from.AllReleaseLinks();
  if (!release_chain.ok()) return release_chain.status();
  if (auto s = to.ImportTrail(*releases, *audit, *chain, *release_chain); !s.ok()) return s;
  auto conversions = from.AllConversions();
  if (!conversions.ok()) return conversions.status();
  if (auto s = to.ImportConversions(*conversions); !s.ok()) return s;
  out.releases = static_cast<int>(releases->size());
  out.audit_rows = static_cast<int>(audit->size());
  out.chain_links = static_cast<int>(chain->size());
  out.release_links = static_cast<int>(release_chain->size());
  auto a = ContentHash(from);
  if (!a.ok()) return a.status();
  auto b = ContentHash(to);
  if (!b.ok()) return b.status();
  if (*a != *b) {
    return absl::DataLossError(absl::StrCat("migrate: content hashes differ after the copy (source ", *a,
                                            ", target ", *b, ")"));
  }
  out.content_sha256 = *a;
  return out;
}

}  // namespace fluxcal::pipeline
