// A recording set's manifest (manifest.json, docs/recording-format.md):
// parsed field by field with messages that name the file, line and field,
// and written back as JSON.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <set>

#include "absl/strings/str_cat.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "io/recording_set_internal.h"
#include "nlohmann/json.hpp"

namespace fluxcal::io {
namespace internal {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

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

// An optional number that, when present, must be positive (or, with
// zero_allowed, not negative): into *out then, else *out unchanged.
template <class T>
absl::Status GetOptionalSignedNumber(const ManifestCtx& ctx, const json& obj, const std::string& key,
                                     const std::string& field, bool zero_allowed, T* out) {
  bool present = false;
  auto v = GetNumber(ctx, obj, key, field, false, 0, &present);
  if (!v.ok()) return v.status();
  if (!present) return absl::OkStatus();
  if (zero_allowed ? *v < 0 : *v <= 0) return ctx.Error(field, zero_allowed ? "must not be negative" : "must be positive");
  *out = *v;
  return absl::OkStatus();
}

// The object j[key] a section's fields are in; missing or not an object:
// refused naming first_field (the section's first required field).
absl::StatusOr<const json*> GetSection(const ManifestCtx& ctx, const json& j, const std::string& key,
                                       const std::string& first_field) {
  auto it = j.find(key);
  if (it == j.end() || !it->is_object()) {
    return ctx.Error(first_field, it == j.end() ? "required field is missing" : "'" + key + "' must be an object",
                     it == j.end() ? 1 : 0);
  }
  return &*it;
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

absl::StatusOr<json> ParseJson(const ManifestCtx& ctx) {
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
  return j;
}

// format and serial.
absl::Status ParseIdentity(const ManifestCtx& ctx, const json& j, Manifest* m) {
  bool present = false;
  auto fmt = GetString(ctx, j, "format", "format", true, &present, 1);
  if (!fmt.ok()) return fmt.status();
  if (*fmt != kRecordingFormatV1) {
    return ctx.Error("format", absl::StrCat("unknown format version '", Printable(*fmt),
                                            "' (supported: ", kRecordingFormatV1, ")"));
  }
  m->format = *fmt;
  auto serial = GetString(ctx, j, "serial", "serial", true, &present, 1);
  if (!serial.ok()) return serial.status();
  if (!IsValidSerial(*serial)) {
    return ctx.Error("serial", absl::StrCat("illegal serial '", Printable(*serial),
                                            "' (1 to 64 characters of A-Z a-z 0-9 - _ .)"));
  }
  m->serial = *serial;
  return absl::OkStatus();
}

// Runs parse(section, line) on the required section j[key] (GetSection
// refuses a missing one, naming first_field), `line` that of its key.
template <typename Parse>
absl::Status InSection(const ManifestCtx& ctx, const json& j, const std::string& key,
                       const std::string& first_field, Parse parse) {
  auto section = GetSection(ctx, j, key, first_field);
  if (!section.ok()) return section.status();
  return parse(**section, LineOfKey(ctx.text, key));
}

absl::Status ParseMotor(const ManifestCtx& ctx, const json& j, Manifest* m) {
  return InSection(ctx, j, "motor", "motor.pole_pairs", [&](const json& mo, size_t hint) -> absl::Status {
    bool present = false;
    auto it = mo.find("pole_pairs");
    if (it == mo.end()) return ctx.Error("motor.pole_pairs", "required field is missing", hint);
    if (!it->is_number_integer() && !(it->is_number() && std::floor(it->get<double>()) == it->get<double>())) {
      return ctx.Error("motor.pole_pairs", absl::StrCat("expected an integer, got ", it->dump()));
    }
    const double pp = it->get<double>();
    if (pp < 1 || pp > 100) {
      return ctx.Error("motor.pole_pairs", absl::StrCat("must be 1..100, got ", it->dump()));
    }
    m->motor.pole_pairs = static_cast<int>(pp);
    if (auto s = GetOptionalSignedNumber(ctx, mo, "rs_ohm", "motor.rs_ohm", true, &m->motor.rs_ohm); !s.ok()) return s;
    if (auto s = GetOptionalSignedNumber(ctx, mo, "psi_pm_wb", "motor.psi_pm_wb", true, &m->motor.psi_pm_wb); !s.ok()) {
      return s;
    }
    auto tc = GetNumber(ctx, mo, "psi_pm_temp_coeff_per_k", "motor.psi_pm_temp_coeff_per_k", false, 0, &present);
    if (!tc.ok()) return tc.status();
    if (present) {
      if (*tc < kMinPsiPmTempCoeffPerK || *tc > kMaxPsiPmTempCoeffPerK) {
        return ctx.Error("motor.psi_pm_temp_coeff_per_k",
                         absl::StrCat("must be in [", kMinPsiPmTempCoeffPerK, ", ", kMaxPsiPmTempCoeffPerK,
                                      "] per kelvin (a relative change, not %/K: NdFeB is about -0.0011), got ",
                                      *tc));
      }
      m->motor.psi_pm_temp_coeff_per_k = *tc;
    }
    return absl::OkStatus();
  });
}

absl::Status ParseDrive(const ManifestCtx& ctx, const json& j, Manifest* m) {
  return InSection(ctx, j, "drive", "drive.f_sample_hz", [&](const json& d, size_t hint) -> absl::Status {
    bool present = false;
    auto fs_hz = GetNumber(ctx, d, "f_sample_hz", "drive.f_sample_hz", true, 0, &present, hint);
    if (!fs_hz.ok()) return fs_hz.status();
    if (*fs_hz <= 0) return ctx.Error("drive.f_sample_hz", "must be positive");
    m->drive.f_sample_hz = *fs_hz;
    for (auto [key, field, zero_allowed, out] :
         {std::tuple{"udc_v", "drive.udc_v", false, &m->drive.udc_v},
          std::tuple{"f_pwm_hz", "drive.f_pwm_hz", false, &m->drive.f_pwm_hz},
          std::tuple{"dead_time_s", "drive.dead_time_s", true, &m->drive.dead_time_s}}) {
      if (auto s = GetOptionalSignedNumber(ctx, d, key, field, zero_allowed, out); !s.ok()) return s;
    }
    auto it = d.find("dead_time_compensated");
    if (it != d.end() && !it->is_null()) {
      if (!it->is_boolean()) {
        return ctx.Error("drive.dead_time_compensated",
                         absl::StrCat("expected true or false, got ", TypeName(*it)));
      }
      m->drive.dead_time_compensated = it->get<bool>();
    }
    return absl::OkStatus();
  });
}

absl::Status ParseInjection(const ManifestCtx& ctx, const json& j, Manifest* m) {
  bool present = false;
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
    if (*f >= m->drive.f_sample_hz / 2) {
      return ctx.Error("injection.frequency_hz",
                       absl::StrCat("must be below half the sample rate (", m->drive.f_sample_hz / 2,
                                    " Hz), got ", *f));
    }
    inj.frequency_hz = *f;
    m->injection = inj;
  }
  return absl::OkStatus();
}

absl::Status ParsePoints(const ManifestCtx& ctx, const json& j, Manifest* m) {
  bool present = false;
  if (auto pit = j.find("points"); pit != j.end() && !pit->is_null()) {
    if (!pit->is_array()) return ctx.Error("points", "expected an array");
    if (!m->injection && !pit->empty()) {
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
      // The references are required; a missing speed is standstill (0).
      for (auto [key, required, out] : {std::tuple{"id_ref_a", true, &ps.id_ref_a},
                                        std::tuple{"iq_ref_a", true, &ps.iq_ref_a},
                                        std::tuple{"speed_rpm", false, &ps.speed_rpm}}) {
        auto v = GetNumber(ctx, p, key, base + "." + key, required, 0.0, &present, line);
        if (!v.ok()) return v.status();
        *out = *v;
      }
      auto temp = GetNumber(ctx, p, "temperature_c", base + ".temperature_c", false, 0, &present, line);
      if (!temp.ok()) return temp.status();
      if (present) ps.temperature_c = *temp;
      m->points.push_back(ps);
    }
  }
  return absl::OkStatus();
}

// The steady-state and HF-results files it names.
absl::Status ParseFileRefs(const ManifestCtx& ctx, const json& j, Manifest* m) {
  bool present = false;
  for (const char* key : {"steady_state", "hf_results"}) {
    auto v = GetString(ctx, j, key, key, false, &present);
    if (!v.ok()) return v.status();
    if (present) {
      if (!IsSafeRelativePath(*v)) {
        return ctx.Error(key, absl::StrCat("path '", Printable(*v), "' must be relative and inside the set"));
      }
      (std::string(key) == "steady_state" ? m->steady_state : m->hf_results) = *v;
    }
  }
  return absl::OkStatus();
}

}  // namespace

// point at the offending line; falls back to line 1.
size_t LineOfKey(const std::string& text, const std::string& key, size_t start_line) {
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

// A referenced file must stay inside the set directory.
bool IsSafeRelativePath(const std::string& p) {
  if (p.empty() || p.front() == '/') return false;
  for (const auto& part : fs::path(p)) {
    if (part == "..") return false;
  }
  return true;
}

absl::StatusOr<Manifest> ParseManifest(const ManifestCtx& ctx) {
  auto j = ParseJson(ctx);
  if (!j.ok()) return j.status();
  if (!j->is_object()) return ctx.Error("(root)", "expected a JSON object", 1);
  Manifest m;
  for (auto* step : {ParseIdentity, ParseMotor, ParseDrive, ParseInjection, ParsePoints, ParseFileRefs}) {
    if (absl::Status s = step(ctx, *j, &m); !s.ok()) return s;
  }
  return m;
}

}  // namespace internal

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
  internal::ManifestCtx ctx{manifest_path, std::move(*text)};
  return internal::ParseManifest(ctx);
}

namespace internal {

// The manifest as JSON, the fields the set states (written last by
// WriteRecordingSet).
nlohmann::json ManifestToJson(const Manifest& m) {
  nlohmann::json j;
  j["format"] = m.format;
  j["serial"] = m.serial;
  nlohmann::json motor;
  motor["pole_pairs"] = m.motor.pole_pairs;
  if (m.motor.rs_ohm) motor["rs_ohm"] = *m.motor.rs_ohm;
  if (m.motor.psi_pm_wb) motor["psi_pm_wb"] = *m.motor.psi_pm_wb;
  if (m.motor.psi_pm_temp_coeff_per_k) motor["psi_pm_temp_coeff_per_k"] = *m.motor.psi_pm_temp_coeff_per_k;
  j["motor"] = motor;
  nlohmann::json drive;
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
    nlohmann::json pts = nlohmann::json::array();
    for (const auto& p : m.points) {
      nlohmann::json pj = {{"id", p.id}, {"file", p.file}, {"id_ref_a", p.id_ref_a},
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

}  // namespace internal
}  // namespace fluxcal::io
