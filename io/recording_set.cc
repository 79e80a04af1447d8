#include "io/recording_set.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <set>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/csv.h"
#include "nlohmann/json.hpp"

namespace fluxcal::io {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// Best-effort line of `"key"` in the manifest text, so that messages can
// point at the offending line; falls back to line 1.
size_t LineOfKey(const std::string& text, const std::string& key, size_t start_line = 1) {
  const std::string needle = absl::StrCat("\"", key, "\"");
  size_t line = 1, pos = 0;
  while (line < start_line && pos < text.size()) {
    pos = text.find('\n', pos);
    if (pos == std::string::npos) return 1;
    ++pos;
    ++line;
  }
  const size_t hit = text.find(needle, pos);
  if (hit == std::string::npos) return start_line;
  return start_line + static_cast<size_t>(std::count(text.begin() + pos, text.begin() + hit, '\n'));
}

// Context for manifest errors: display path + text for line lookup.
struct ManifestCtx {
  std::string path;
  std::string text;
  absl::Status Error(const std::string& field, const std::string& what,
                     size_t line = 0) const {
    if (line == 0) {
      const auto dot = field.find_last_of('.');
      std::string leaf = dot == std::string::npos ? field : field.substr(dot + 1);
      const auto br = leaf.find('[');
      if (br != std::string::npos) leaf = leaf.substr(0, br);
      line = LineOfKey(text, leaf);
    }
    return absl::InvalidArgumentError(
        absl::StrCat(path, ":", line, ": field '", field, "': ", what));
  }
};

std::string TypeName(const json& j) { return j.type_name(); }

absl::StatusOr<double> GetNumber(const ManifestCtx& ctx, const json& obj,
                                 const std::string& key, const std::string& field,
                                 bool required, double fallback, bool* present,
                                 size_t line_hint = 0) {
  *present = false;
  auto it = obj.find(key);
  if (it == obj.end() || it->is_null()) {
    if (required) return ctx.Error(field, "required field is missing", line_hint);
    return fallback;
  }
  if (!it->is_number()) {
    return ctx.Error(field, absl::StrCat("expected a number, got ", TypeName(*it)), line_hint);
  }
  const double v = it->get<double>();
  if (!std::isfinite(v)) return ctx.Error(field, "expected a finite number", line_hint);
  *present = true;
  return v;
}

absl::StatusOr<std::string> GetString(const ManifestCtx& ctx, const json& obj,
                                      const std::string& key, const std::string& field,
                                      bool required, bool* present, size_t line_hint = 0) {
  *present = false;
  auto it = obj.find(key);
  if (it == obj.end() || it->is_null()) {
    if (required) return ctx.Error(field, "required field is missing", line_hint);
    return std::string();
  }
  if (!it->is_string()) {
    return ctx.Error(field, absl::StrCat("expected a string, got ", TypeName(*it)), line_hint);
  }
  *present = true;
  return it->get<std::string>();
}

// A referenced file must stay inside the set directory.
bool IsSafeRelativePath(const std::string& p) {
  if (p.empty() || p.front() == '/') return false;
  for (const auto& part : fs::path(p)) {
    if (part == "..") return false;
  }
  return true;
}

absl::StatusOr<Manifest> ParseManifest(const ManifestCtx& ctx) {
  json j;
  try {
    j = json::parse(ctx.text);
  } catch (const json::parse_error& e) {
    // Convert the byte offset to a line number.
    const size_t off = std::min<size_t>(e.byte, ctx.text.size());
    const size_t line = 1 + static_cast<size_t>(
        std::count(ctx.text.begin(), ctx.text.begin() + off, '\n'));
    return absl::InvalidArgumentError(absl::StrCat(
        ctx.path, ":", line, ": field '(json)': syntax error: ", Printable(e.what())));
  } catch (const json::exception& e) {
    // out_of_range 406: a number that overflows a double (1e999, a
    // 400-digit integer). The parser does not say where; the message does.
    return absl::InvalidArgumentError(absl::StrCat(
        ctx.path, ":1: field '(json)': ", Printable(e.what())));
  }
  if (!j.is_object()) return ctx.Error("(root)", "expected a JSON object", 1);

  Manifest m;
  bool present = false;
  auto fmt = GetString(ctx, j, "format", "format", true, &present, 1);
  if (!fmt.ok()) return fmt.status();
  if (*fmt != kRecordingFormatV1) {
    return ctx.Error("format", absl::StrCat("unknown format version '", Printable(*fmt),
                                            "' (supported: ", kRecordingFormatV1, ")"));
  }
  m.format = *fmt;
  auto serial = GetString(ctx, j, "serial", "serial", true, &present, 1);
  if (!serial.ok()) return serial.status();
  if (!IsValidSerial(*serial)) {
    return ctx.Error("serial", absl::StrCat("illegal serial '", Printable(*serial),
                                            "' (1 to 64 characters of A-Z a-z 0-9 - _ .)"));
  }
  m.serial = *serial;

  // motor
  auto mit = j.find("motor");
  if (mit == j.end() || !mit->is_object()) {
    return ctx.Error("motor.pole_pairs",
                     mit == j.end() ? "required field is missing" : "'motor' must be an object",
                     mit == j.end() ? 1 : 0);
  }
  {
    const json& mo = *mit;
    const size_t hint = LineOfKey(ctx.text, "motor");
    auto it = mo.find("pole_pairs");
    if (it == mo.end()) return ctx.Error("motor.pole_pairs", "required field is missing", hint);
    if (!it->is_number_integer() && !(it->is_number() && std::floor(it->get<double>()) == it->get<double>())) {
      return ctx.Error("motor.pole_pairs", absl::StrCat("expected an integer, got ", it->dump()));
    }
    const double pp = it->get<double>();
    if (pp < 1 || pp > 100) {
      return ctx.Error("motor.pole_pairs", absl::StrCat("must be 1..100, got ", it->dump()));
    }
    m.motor.pole_pairs = static_cast<int>(pp);
    auto rs = GetNumber(ctx, mo, "rs_ohm", "motor.rs_ohm", false, 0, &present);
    if (!rs.ok()) return rs.status();
    if (present) {
      if (*rs < 0) return ctx.Error("motor.rs_ohm", "must not be negative");
      m.motor.rs_ohm = *rs;
    }
    auto pm = GetNumber(ctx, mo, "psi_pm_wb", "motor.psi_pm_wb", false, 0, &present);
    if (!pm.ok()) return pm.status();
    if (present) {
      if (*pm < 0) return ctx.Error("motor.psi_pm_wb", "must not be negative");
      m.motor.psi_pm_wb = *pm;
    }
  }

  // drive
  auto dit = j.find("drive");
  if (dit == j.end() || !dit->is_object()) {
    return ctx.Error("drive.f_sample_hz",
                     dit == j.end() ? "required field is missing" : "'drive' must be an object",
                     dit == j.end() ? 1 : 0);
  }
  {
    const json& d = *dit;
    const size_t hint = LineOfKey(ctx.text, "drive");
    auto fs_hz = GetNumber(ctx, d, "f_sample_hz", "drive.f_sample_hz", true, 0, &present, hint);
    if (!fs_hz.ok()) return fs_hz.status();
    if (*fs_hz <= 0) return ctx.Error("drive.f_sample_hz", "must be positive");
    m.drive.f_sample_hz = *fs_hz;
    auto udc = GetNumber(ctx, d, "udc_v", "drive.udc_v", false, 0, &present);
    if (!udc.ok()) return udc.status();
    if (present) {
      if (*udc <= 0) return ctx.Error("drive.udc_v", "must be positive");
      m.drive.udc_v = *udc;
    }
    auto fpwm = GetNumber(ctx, d, "f_pwm_hz", "drive.f_pwm_hz", false, 0, &present);
    if (!fpwm.ok()) return fpwm.status();
    if (present) {
      if (*fpwm <= 0) return ctx.Error("drive.f_pwm_hz", "must be positive");
      m.drive.f_pwm_hz = *fpwm;
    }
    auto td = GetNumber(ctx, d, "dead_time_s", "drive.dead_time_s", false, 0, &present);
    if (!td.ok()) return td.status();
    if (present) {
      if (*td < 0) return ctx.Error("drive.dead_time_s", "must not be negative");
      m.drive.dead_time_s = *td;
    }
    auto it = d.find("dead_time_compensated");
    if (it != d.end() && !it->is_null()) {
      if (!it->is_boolean()) {
        return ctx.Error("drive.dead_time_compensated",
                         absl::StrCat("expected true or false, got ", TypeName(*it)));
      }
      m.drive.dead_time_compensated = it->get<bool>();
    }
  }

  // injection
  if (auto iit = j.find("injection"); iit != j.end() && !iit->is_null()) {
    if (!iit->is_object()) return ctx.Error("injection", "expected an object");
    InjectionInfo inj;
    const size_t hint = LineOfKey(ctx.text, "injection");
    auto type = GetString(ctx, *iit, "type", "injection.type", true, &present, hint);
    if (!type.ok()) return type.status();
    if (*type != "rotating") {
      return ctx.Error("injection.type",
                       absl::StrCat("unsupported injection type '", Printable(*type), "' (supported: rotating)"));
    }
    inj.type = *type;
    auto amp = GetNumber(ctx, *iit, "amplitude_v", "injection.amplitude_v", true, 0, &present, hint);
    if (!amp.ok()) return amp.status();
    if (*amp <= 0) return ctx.Error("injection.amplitude_v", "must be positive");
    inj.amplitude_v = *amp;
    auto f = GetNumber(ctx, *iit, "frequency_hz", "injection.frequency_hz", true, 0, &present, hint);
    if (!f.ok()) return f.status();
    if (*f <= 0) return ctx.Error("injection.frequency_hz", "must be positive");
    if (*f >= m.drive.f_sample_hz / 2) {
      return ctx.Error("injection.frequency_hz",
                       absl::StrCat("must be below half the sample rate (", m.drive.f_sample_hz / 2,
                                    " Hz), got ", *f));
    }
    inj.frequency_hz = *f;
    m.injection = inj;
  }

  // points
  if (auto pit = j.find("points"); pit != j.end() && !pit->is_null()) {
    if (!pit->is_array()) return ctx.Error("points", "expected an array");
    if (!m.injection && !pit->empty()) {
      return ctx.Error("injection", "required when 'points' is present", 1);
    }
    std::set<std::string> ids, files;
    size_t search_line = LineOfKey(ctx.text, "points");
    for (size_t k = 0; k < pit->size(); ++k) {
      const json& p = (*pit)[k];
      const std::string base = absl::StrCat("points[", k, "]");
      const size_t line = LineOfKey(ctx.text, "id", search_line);
      search_line = line;
      if (!p.is_object()) return ctx.Error(base, "expected an object", line);
      PointSpec ps;
      auto id = GetString(ctx, p, "id", base + ".id", true, &present, line);
      if (!id.ok()) return id.status();
      if (id->empty() || !IsValidSerial(*id)) {
        return ctx.Error(base + ".id", absl::StrCat("illegal point id '", Printable(*id), "'"), line);
      }
      if (!ids.insert(*id).second) {
        return ctx.Error(base + ".id", absl::StrCat("duplicate point id '", Printable(*id), "'"), line);
      }
      ps.id = *id;
      auto file = GetString(ctx, p, "file", base + ".file", true, &present, line);
      if (!file.ok()) return file.status();
      if (!IsSafeRelativePath(*file)) {
        return ctx.Error(base + ".file",
                         absl::StrCat("path '", Printable(*file), "' must be relative and inside the set"), line);
      }
      ps.file = *file;
      auto idr = GetNumber(ctx, p, "id_ref_a", base + ".id_ref_a", true, 0, &present, line);
      if (!idr.ok()) return idr.status();
      ps.id_ref_a = *idr;
      auto iqr = GetNumber(ctx, p, "iq_ref_a", base + ".iq_ref_a", true, 0, &present, line);
      if (!iqr.ok()) return iqr.status();
      ps.iq_ref_a = *iqr;
      auto spd = GetNumber(ctx, p, "speed_rpm", base + ".speed_rpm", false, 0.0, &present, line);
      if (!spd.ok()) return spd.status();
      ps.speed_rpm = *spd;
      auto temp = GetNumber(ctx, p, "temperature_c", base + ".temperature_c", false, 0, &present, line);
      if (!temp.ok()) return temp.status();
      if (present) ps.temperature_c = *temp;
      m.points.push_back(ps);
    }
  }

  for (const char* key : {"steady_state", "hf_results"}) {
    auto v = GetString(ctx, j, key, key, false, &present);
    if (!v.ok()) return v.status();
    if (present) {
      if (!IsSafeRelativePath(*v)) {
        return ctx.Error(key, absl::StrCat("path '", Printable(*v), "' must be relative and inside the set"));
      }
      (std::string(key) == "steady_state" ? m.steady_state : m.hf_results) = *v;
    }
  }
  return m;
}

const std::vector<CsvColumnSpec>& WaveformSpec() {
  static const std::vector<CsvColumnSpec> spec = {
      {"t_s"}, {"ia_a"}, {"ib_a"}, {"ic_a"}, {"theta_e_rad"},
      {"ualpha_ref_v"}, {"ubeta_ref_v"}, {"udc_v", true}};
  return spec;
}
const std::vector<CsvColumnSpec>& SteadyStateSpec() {
  static const std::vector<CsvColumnSpec> spec = {
      {"id_a"}, {"iq_a"}, {"speed_rpm"}, {"ud_ref_v"}, {"uq_ref_v"},
      {"torque_nm", true}, {"temperature_c", true}};
  return spec;
}
// The compatible extension of steady_state.csv (docs/recording-format.md,
// "Rows a bench could not hold"): after the standard columns, in any order.
const std::vector<CsvColumnSpec>& SteadyStateExtension() {
  static const std::vector<CsvColumnSpec> spec = {
      {"current_ripple_a", true}, {"voltage_limited_share", true}, {"controller_saturated_share", true}};
  return spec;
}
const std::vector<CsvColumnSpec>& HfResultsSpec() {
  static const std::vector<CsvColumnSpec> spec = {
      {"id_a"}, {"iq_a"}, {"speed_rpm"}, {"ld_h"}, {"lq_h"},
      {"ldq_h", true}, {"temperature_c", true}};
  return spec;
}

std::optional<double> Opt(double v) {
  return std::isnan(v) ? std::nullopt : std::optional<double>(v);
}

absl::StatusOr<Waveform> ReadWaveform(std::string_view text, const std::string& display,
                                      const Manifest& m) {
  auto table = ParseNumericCsv(text, display, WaveformSpec());
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

std::string Fmt(double v) { return absl::StrFormat("%.10g", v); }
std::string FmtOpt(const std::optional<double>& v) { return v ? Fmt(*v) : std::string(); }

}  // namespace

bool IsValidSerial(const std::string& serial) {
  if (serial.empty() || serial.size() > 64) return false;
  // "." and ".." (any all-dot name) read as paths, not serials.
  if (serial.find_first_not_of('.') == std::string::npos) return false;
  for (char c : serial) {
    const bool ok = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                    c == '-' || c == '_' || c == '.';
    if (!ok) return false;
  }
  return true;
}

absl::StatusOr<Manifest> ReadManifest(const std::string& manifest_path) {
  auto text = ReadFileToString(manifest_path);
  if (!text.ok()) {
    return absl::NotFoundError(absl::StrCat(manifest_path, ":1: field '(file)': manifest not found"));
  }
  ManifestCtx ctx{manifest_path, std::move(*text)};
  return ParseManifest(ctx);
}

namespace {

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
  auto t = ParseNumericCsv(text, path, SteadyStateSpec(), SteadyStateExtension());
  if (!t.ok()) return t.status();
  std::vector<SteadyStateRow> rows(t->rows);
  for (size_t r = 0; r < t->rows; ++r) {
    auto& o = rows[r];
    o.id_a = t->columns[0][r];
    o.iq_a = t->columns[1][r];
    o.speed_rpm = t->columns[2][r];
    o.ud_ref_v = t->columns[3][r];
    o.uq_ref_v = t->columns[4][r];
    o.torque_nm = Opt(t->columns[5][r]);
    o.temperature_c = Opt(t->columns[6][r]);
    o.current_ripple_a = Opt(t->columns[7][r]);
    o.voltage_limited_share = Opt(t->columns[8][r]);
    o.controller_saturated_share = Opt(t->columns[9][r]);
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
  auto t = ParseNumericCsv(text, path, HfResultsSpec());
  if (!t.ok()) return t.status();
  std::vector<HfResultRow> rows(t->rows);
  for (size_t r = 0; r < t->rows; ++r) {
    auto& o = rows[r];
    o.id_a = t->columns[0][r];
    o.iq_a = t->columns[1][r];
    o.speed_rpm = t->columns[2][r];
    o.ld_h = t->columns[3][r];
    o.lq_h = t->columns[4][r];
    o.ldq_h = Opt(t->columns[5][r]);
    o.temperature_c = Opt(t->columns[6][r]);
    // A non-positive inductance is well-formed data (a real map can fall in
    // id near zero current): the fit excludes it and says so
    // (fit::FitSummary::excluded), instead of the whole file failing here.
  }
  return rows;
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
  if (mf.steady_state) {
    const std::string* text = src.Read(*mf.steady_state);
    if (text == nullptr) return missing("steady_state", "steady_state", *mf.steady_state);
    auto rows = ParseSteadyState(*text, src.Display(*mf.steady_state));
    if (!rows.ok()) return rows.status();
    set.steady_state = std::move(*rows);
  }
  if (mf.hf_results) {
    const std::string* text = src.Read(*mf.hf_results);
    if (text == nullptr) return missing("hf_results", "hf_results", *mf.hf_results);
    auto rows = ParseHfResults(*text, src.Display(*mf.hf_results));
    if (!rows.ok()) return rows.status();
    set.hf_results = std::move(*rows);
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

nlohmann::json ManifestToJson(const Manifest& m) {
  json j;
  j["format"] = m.format;
  j["serial"] = m.serial;
  json motor;
  motor["pole_pairs"] = m.motor.pole_pairs;
  if (m.motor.rs_ohm) motor["rs_ohm"] = *m.motor.rs_ohm;
  if (m.motor.psi_pm_wb) motor["psi_pm_wb"] = *m.motor.psi_pm_wb;
  j["motor"] = motor;
  json drive;
  if (m.drive.udc_v) drive["udc_v"] = *m.drive.udc_v;
  if (m.drive.f_pwm_hz) drive["f_pwm_hz"] = *m.drive.f_pwm_hz;
  drive["f_sample_hz"] = m.drive.f_sample_hz;
  if (m.drive.dead_time_s) drive["dead_time_s"] = *m.drive.dead_time_s;
  if (m.drive.dead_time_compensated) drive["dead_time_compensated"] = *m.drive.dead_time_compensated;
  j["drive"] = drive;
  if (m.injection) {
    j["injection"] = {{"type", m.injection->type},
                      {"amplitude_v", m.injection->amplitude_v},
                      {"frequency_hz", m.injection->frequency_hz}};
  }
  if (!m.points.empty()) {
    json pts = json::array();
    for (const auto& p : m.points) {
      json pj = {{"id", p.id}, {"file", p.file}, {"id_ref_a", p.id_ref_a},
                 {"iq_ref_a", p.iq_ref_a}, {"speed_rpm", p.speed_rpm}};
      if (p.temperature_c) pj["temperature_c"] = *p.temperature_c;
      pts.push_back(pj);
    }
    j["points"] = pts;
  }
  if (m.steady_state) j["steady_state"] = *m.steady_state;
  if (m.hf_results) j["hf_results"] = *m.hf_results;
  return j;
}

std::string WaveformToCsv(const Waveform& w) {
  std::string out = "t_s,ia_a,ib_a,ic_a,theta_e_rad,ualpha_ref_v,ubeta_ref_v,udc_v\n";
  out.reserve(w.size() * 110);
  char buf[256];
  for (size_t k = 0; k < w.size(); ++k) {
    const double udc = k < w.udc_v.size() ? w.udc_v[k] : std::nan("");
    int n = std::snprintf(buf, sizeof buf, "%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,", w.t_s[k],
                          w.ia_a[k], w.ib_a[k], w.ic_a[k], w.theta_e_rad[k], w.ualpha_ref_v[k],
                          w.ubeta_ref_v[k]);
    out.append(buf, n);
    if (!std::isnan(udc)) {
      n = std::snprintf(buf, sizeof buf, "%.9g", udc);
      out.append(buf, n);
    }
    out.push_back('\n');
  }
  return out;
}

absl::Status WriteHfResultsCsv(const std::string& path, const std::vector<HfResultRow>& rows) {
  std::string out = "id_a,iq_a,speed_rpm,ld_h,lq_h,ldq_h,temperature_c\n";
  for (const auto& r : rows) {
    absl::StrAppend(&out, Fmt(r.id_a), ",", Fmt(r.iq_a), ",", Fmt(r.speed_rpm), ",", Fmt(r.ld_h),
                    ",", Fmt(r.lq_h), ",", FmtOpt(r.ldq_h), ",", FmtOpt(r.temperature_c), "\n");
  }
  return WriteFileAtomically(path, out);
}

absl::Status WriteSteadyStateCsv(const std::string& path, const std::vector<SteadyStateRow>& rows) {
  // The extension columns only when a row holds one (recording_set.h).
  bool extended = false;
  for (const auto& r : rows) {
    extended |= r.current_ripple_a || r.voltage_limited_share || r.controller_saturated_share;
  }
  std::string out = "id_a,iq_a,speed_rpm,ud_ref_v,uq_ref_v,torque_nm,temperature_c";
  if (extended) out += ",current_ripple_a,voltage_limited_share,controller_saturated_share";
  out += "\n";
  for (const auto& r : rows) {
    absl::StrAppend(&out, Fmt(r.id_a), ",", Fmt(r.iq_a), ",", Fmt(r.speed_rpm), ",",
                    Fmt(r.ud_ref_v), ",", Fmt(r.uq_ref_v), ",", FmtOpt(r.torque_nm), ",",
                    FmtOpt(r.temperature_c));
    if (extended) {
      absl::StrAppend(&out, ",", FmtOpt(r.current_ripple_a), ",", FmtOpt(r.voltage_limited_share), ",",
                      FmtOpt(r.controller_saturated_share));
    }
    out += "\n";
  }
  return WriteFileAtomically(path, out);
}

absl::Status WriteRecordingSet(const std::string& dir, const RecordingSet& set) {
  const Manifest& m = set.manifest;
  if (!IsValidSerial(m.serial)) {
    return absl::InvalidArgumentError(absl::StrCat("serial '", m.serial, "' is illegal"));
  }
  if (set.waveforms.size() != m.points.size()) {
    return absl::InvalidArgumentError(absl::StrCat("set has ", m.points.size(), " points but ",
                                                   set.waveforms.size(), " waveforms"));
  }
  std::error_code ec;
  const fs::path root(dir);
  fs::create_directories(root, ec);
  if (ec) return absl::PermissionDeniedError(absl::StrCat(dir, ": ", ec.message()));
  for (size_t k = 0; k < m.points.size(); ++k) {
    if (!IsSafeRelativePath(m.points[k].file)) {
      return absl::InvalidArgumentError(absl::StrCat("points[", k, "].file: path must be relative"));
    }
    const fs::path p = root / m.points[k].file;
    fs::create_directories(p.parent_path(), ec);
    if (ec) return absl::PermissionDeniedError(absl::StrCat(p.string(), ": ", ec.message()));
    if (auto s = WriteFileAtomically(p.string(), WaveformToCsv(set.waveforms[k])); !s.ok()) return s;
  }
  if (m.steady_state) {
    if (auto s = WriteSteadyStateCsv((root / *m.steady_state).string(), set.steady_state); !s.ok()) {
      return s;
    }
  }
  if (m.hf_results) {
    if (auto s = WriteHfResultsCsv((root / *m.hf_results).string(), set.hf_results); !s.ok()) {
      return s;
    }
  }
  // The manifest goes last: a set whose manifest exists is complete.
  return WriteFileAtomically((root / "manifest.json").string(), ManifestToJson(m).dump(2) + "\n");
}

}  // namespace fluxcal::io
