// Reading a recording set (docs/recording-format.md) from a directory or
// from files held in memory: the manifest (manifest.cc), each point's
// waveform with its time base checked against the manifest, the
// steady-state and HF-results tables; the rule for the files' names.
// Writing one is recording_set_write.cc.
#include "io/recording_set.h"

#include <cmath>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/csv.h"
#include "io/recording_set_internal.h"

namespace fluxcal::io {
namespace {

namespace fs = std::filesystem;
using internal::LineOfKey;
using internal::ManifestCtx;
using internal::ParseManifest;

// The columns of each CSV of a set (docs/recording-format.md), built once.
struct CsvSpecs {
  std::vector<CsvColumnSpec> waveform, steady_state, hf_results;
  // The compatible extension of steady_state.csv ("Rows a bench could not
  // hold"): after the standard columns, in any order.
  std::vector<CsvColumnSpec> steady_state_extension;
};
const CsvSpecs& Specs() {
  static const CsvSpecs specs = {
      /*waveform=*/{{"t_s"}, {"ia_a"}, {"ib_a"}, {"ic_a"}, {"theta_e_rad"},
                    {"ualpha_ref_v"}, {"ubeta_ref_v"}, {"udc_v", true}},
      /*steady_state=*/{{"id_a"}, {"iq_a"}, {"speed_rpm"}, {"ud_ref_v"}, {"uq_ref_v"},
                        {"torque_nm", true}, {"temperature_c", true}},
      /*hf_results=*/{{"id_a"}, {"iq_a"}, {"speed_rpm"}, {"ld_h"}, {"lq_h"},
                      {"ldq_h", true}, {"temperature_c", true}},
      /*steady_state_extension=*/{{"current_ripple_a", true}, {"voltage_limited_share", true},
                                  {"controller_saturated_share", true}}};
  return specs;
}

std::optional<double> Opt(double v) {
  return std::isnan(v) ? std::nullopt : std::optional<double>(v);
}

// The rows of a parsed per-point CSV: its spec's required columns, in
// order, into the `required` fields and the optional columns after them
// into the `optional` ones (an empty cell: no value).
template <typename Row>
std::vector<Row> ToRows(const CsvTable& t, std::initializer_list<double Row::*> required,
                        std::initializer_list<std::optional<double> Row::*> optional) {
  std::vector<Row> rows(t.rows);
  for (size_t r = 0; r < t.rows; ++r) {
    size_t c = 0;
    for (double Row::*field : required) rows[r].*field = t.columns[c++][r];
    for (std::optional<double> Row::*field : optional) rows[r].*field = Opt(t.columns[c++][r]);
  }
  return rows;
}

absl::StatusOr<Waveform> ReadWaveform(std::string_view text, const std::string& display,
                                      const Manifest& m) {
  auto table = ParseNumericCsv(text, display, Specs().waveform);
  if (!table.ok()) return table.status();
  Waveform w;
  w.t_s = std::move(table->columns[0]);
  w.ia_a = std::move(table->columns[1]);
  w.ib_a = std::move(table->columns[2]);
  w.ic_a = std::move(table->columns[3]);
  w.theta_e_rad = std::move(table->columns[4]);
  w.ualpha_ref_v = std::move(table->columns[5]);
  w.ubeta_ref_v = std::move(table->columns[6]);
  w.udc_v = std::move(table->columns[7]);
  const size_t n = w.size();
  if (n < 2) {
    return absl::InvalidArgumentError(
        absl::StrCat(display, ":2: field 't_s': need at least 2 samples, got ", n));
  }
  // Time: strictly increasing, equally spaced at 1/f_sample_hz. Tolerance 1%
  // of the period covers printing precision (e.g. 4 decimals at 10 kHz).
  const double ts = 1.0 / m.drive.f_sample_hz;
  const double tol = 0.01 * ts;
  for (size_t k = 1; k < n; ++k) {
    const double dt = w.t_s[k] - w.t_s[k - 1];
    if (dt <= 0) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s:%d: field 't_s': time not increasing (%.9g after %.9g)", display, k + 2,
          w.t_s[k], w.t_s[k - 1]));
    }
    if (std::abs(dt - ts) > tol) {
      // Distinguish a consistently different rate from an uneven spacing.
      const double mean_dt = (w.t_s[n - 1] - w.t_s[0]) / static_cast<double>(n - 1);
      if (std::abs(mean_dt - ts) > tol) {
        return absl::InvalidArgumentError(absl::StrFormat(
            "%s:%d: field 't_s': sample interval %.9g s disagrees with manifest "
            "drive.f_sample_hz = %.9g Hz (interval %.9g s)",
            display, k + 2, dt, m.drive.f_sample_hz, ts));
      }
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s:%d: field 't_s': unevenly spaced time (step %.9g s, expected %.9g s)",
          display, k + 2, dt, ts));
    }
  }
  for (size_t k = 0; k < n; ++k) {
    if (!std::isnan(w.udc_v[k]) && w.udc_v[k] <= 0) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s:%d: field 'udc_v': must be positive, got %.9g", display, k + 2, w.udc_v[k]));
    }
  }
  if (m.injection) {
    const double periods = static_cast<double>(n) / m.drive.f_sample_hz * m.injection->frequency_hz;
    if (periods < 10.0 - 1e-9) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s:%d: field 't_s': %d samples hold %.2f injection periods at %.6g Hz; at least 10 "
          "are required",
          display, n + 1, n, periods, m.injection->frequency_hz));
    }
  }
  return w;
}

// Where a set's files come from: a directory on disk, or names and contents
// held in memory (a set received over the network is never written to disk).
class SetSource {
 public:
  virtual ~SetSource() = default;
  // Contents of the file `rel` (relative to the set root), nullptr when it is
  // absent. The pointer stays valid until the next call.
  virtual const std::string* Read(const std::string& rel) = 0;
  // The name used in messages for `rel`.
  virtual std::string Display(const std::string& rel) const = 0;
};

class DirSource final : public SetSource {
 public:
  explicit DirSource(fs::path root) : root_(std::move(root)) {}
  const std::string* Read(const std::string& rel) override {
    std::error_code ec;
    const fs::path p = root_ / rel;
    if (!fs::is_regular_file(p, ec)) return nullptr;
    auto text = ReadFileToString(p.string());
    if (!text.ok()) return nullptr;
    buf_ = std::move(*text);
    return &buf_;
  }
  std::string Display(const std::string& rel) const override { return (root_ / rel).string(); }

 private:
  fs::path root_;
  std::string buf_;
};

class MemorySource final : public SetSource {
 public:
  MemorySource(const RecordingFiles& files, std::string display_root)
      : files_(files), root_(std::move(display_root)) {}
  const std::string* Read(const std::string& rel) override {
    // Manifest references are compared after lexical normalisation
    // ("./points/p0.csv" names "points/p0.csv"); the stored names are
    // already canonical (ValidateRecordingFileName).
    auto it = files_.find(fs::path(rel).lexically_normal().generic_string());
    return it == files_.end() ? nullptr : &it->second;
  }
  std::string Display(const std::string& rel) const override {
    return root_.empty() ? rel : absl::StrCat(root_, "/", rel);
  }

 private:
  const RecordingFiles& files_;
  std::string root_;
};

absl::StatusOr<std::vector<SteadyStateRow>> ParseSteadyState(std::string_view text, const std::string& path) {
  auto t = ParseNumericCsv(text, path, Specs().steady_state, Specs().steady_state_extension);
  if (!t.ok()) return t.status();
  using S = SteadyStateRow;
  std::vector<SteadyStateRow> rows =
      ToRows<S>(*t, {&S::id_a, &S::iq_a, &S::speed_rpm, &S::ud_ref_v, &S::uq_ref_v},
                {&S::torque_nm, &S::temperature_c, &S::current_ripple_a, &S::voltage_limited_share,
                 &S::controller_saturated_share});
  for (size_t r = 0; r < rows.size(); ++r) {
    const SteadyStateRow& o = rows[r];
    // Rows are numbered from the header (line 1); the parser allows no
    // blank line between rows.
    const size_t line = r + 2;
    if (o.current_ripple_a && *o.current_ripple_a < 0) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s:%d: field 'current_ripple_a': an RMS must not be negative, got %.9g A", path, line,
          *o.current_ripple_a));
    }
    auto share = [&](const char* name, const std::optional<double>& v) {
      if (!v || (*v >= 0 && *v <= 1)) return absl::OkStatus();
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s:%d: field '%s': a share of the averaging window, expected 0..1, got %.9g", path, line, name, *v));
    };
    if (auto s = share("voltage_limited_share", o.voltage_limited_share); !s.ok()) return s;
    if (auto s = share("controller_saturated_share", o.controller_saturated_share); !s.ok()) return s;
  }
  return rows;
}

absl::StatusOr<std::vector<HfResultRow>> ParseHfResults(std::string_view text, const std::string& path) {
  auto t = ParseNumericCsv(text, path, Specs().hf_results);
  if (!t.ok()) return t.status();
  // A non-positive inductance is well-formed data (a real map can fall in
  // id near zero current): the fit excludes it and says so
  // (fit::FitSummary::excluded), instead of the whole file failing here.
  using H = HfResultRow;
  return ToRows<H>(*t, {&H::id_a, &H::iq_a, &H::speed_rpm, &H::ld_h, &H::lq_h}, {&H::ldq_h, &H::temperature_c});
}

absl::StatusOr<RecordingSet> ReadSet(SetSource& src, const std::string& root_dir) {
  RecordingSet set;
  set.root_dir = root_dir;
  const std::string manifest_path = src.Display("manifest.json");
  const std::string* mtext = src.Read("manifest.json");
  if (mtext == nullptr) {
    return absl::NotFoundError(absl::StrCat(manifest_path, ":1: field '(file)': manifest not found"));
  }
  ManifestCtx ctx{manifest_path, *mtext};
  auto m = ParseManifest(ctx);
  if (!m.ok()) return m.status();
  set.manifest = std::move(*m);
  const Manifest& mf = set.manifest;
  auto missing = [&](const std::string& field, const std::string& key, const std::string& file) {
    return absl::NotFoundError(absl::StrCat(manifest_path, ":", LineOfKey(ctx.text, key), ": field '", field,
                                            "': referenced file '", Printable(file), "' not found"));
  };
  set.waveforms.reserve(mf.points.size());
  for (size_t k = 0; k < mf.points.size(); ++k) {
    const std::string* text = src.Read(mf.points[k].file);
    if (text == nullptr) {
      return missing(absl::StrCat("points[", k, "].file"), mf.points[k].file, mf.points[k].file);
    }
    auto w = ReadWaveform(*text, src.Display(mf.points[k].file), mf);
    if (!w.ok()) return w.status();
    set.waveforms.push_back(std::move(*w));
  }
  // The table the manifest names under `key` (a field of its own name),
  // read and parsed into *out.
  auto read_table = [&](const char* key, const std::string& file, auto parse, auto* out) -> absl::Status {
    const std::string* text = src.Read(file);
    if (text == nullptr) return missing(key, key, file);
    auto rows = parse(*text, src.Display(file));
    if (!rows.ok()) return rows.status();
    *out = std::move(*rows);
    return absl::OkStatus();
  };
  if (mf.steady_state) {
    if (auto s = read_table("steady_state", *mf.steady_state, ParseSteadyState, &set.steady_state); !s.ok()) return s;
  }
  if (mf.hf_results) {
    if (auto s = read_table("hf_results", *mf.hf_results, ParseHfResults, &set.hf_results); !s.ok()) return s;
  }
  if (mf.points.empty() && !mf.hf_results && !mf.steady_state) {
    return absl::InvalidArgumentError(absl::StrCat(
        manifest_path, ":1: field 'points': the set holds no points, steady_state or hf_results"));
  }
  return set;
}

}  // namespace

absl::StatusOr<std::vector<SteadyStateRow>> ReadSteadyStateCsv(const std::string& path) {
  auto text = ReadFileToString(path);
  if (!text.ok()) return absl::NotFoundError(absl::StrCat(path, ": referenced file not found"));
  return ParseSteadyState(*text, path);
}

absl::StatusOr<std::vector<HfResultRow>> ReadHfResultsCsv(const std::string& path) {
  auto text = ReadFileToString(path);
  if (!text.ok()) return absl::NotFoundError(absl::StrCat(path, ": referenced file not found"));
  return ParseHfResults(*text, path);
}

absl::StatusOr<RecordingSet> ReadRecordingSet(const std::string& dir) {
  std::error_code ec;
  if (!fs::is_directory(fs::path(dir), ec)) {
    return absl::NotFoundError(absl::StrCat(dir, ": not a directory"));
  }
  DirSource src{fs::path(dir)};
  return ReadSet(src, dir);
}

absl::StatusOr<RecordingSet> ReadRecordingSetFromFiles(const RecordingFiles& files,
                                                       const std::string& display_root) {
  for (const auto& [name, data] : files) {
    if (auto s = ValidateRecordingFileName(name); !s.ok()) return s;
  }
  MemorySource src(files, display_root);
  return ReadSet(src, std::string());
}

absl::Status ValidateRecordingFileName(std::string_view name) {
  auto bad = [&](const std::string& why) {
    return absl::InvalidArgumentError(
        absl::StrCat("file '", Printable(name.substr(0, 120)), name.size() > 120 ? "...'" : "'",
                     ": illegal file name in a recording set (", why, ")"));
  };
  if (name.empty()) return bad("empty");
  if (name.size() > kMaxRecordingFileNameBytes) {
    return bad(absl::StrCat("longer than ", kMaxRecordingFileNameBytes, " bytes"));
  }
  if (name.front() == '/') return bad("absolute path");
  int depth = 0;
  size_t start = 0;
  while (start <= name.size()) {
    size_t end = name.find('/', start);
    if (end == std::string_view::npos) end = name.size();
    const std::string_view part = name.substr(start, end - start);
    if (part.empty()) return bad("empty path component");
    if (part == "." || part == "..") return bad("'.' or '..' component");
    for (char c : part) {
      const bool ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                      c == '-' || c == '_' || c == '.';
      if (!ok) return bad("only A-Z a-z 0-9 - _ . and '/' between components");
    }
    if (++depth > kMaxRecordingFileDepth) {
      return bad(absl::StrCat("more than ", kMaxRecordingFileDepth, " levels"));
    }
    start = end + 1;
  }
  return absl::OkStatus();
}


double EffectiveUdc(const RecordingSet& set, size_t point, size_t sample) {
  const double v = set.waveforms[point].udc_v[sample];
  if (!std::isnan(v)) return v;
  return set.manifest.drive.udc_v.value_or(std::nan(""));
}

}  // namespace fluxcal::io
