// Writing a recording set: each point's waveform, the steady-state and
// HF-results tables as CSV, the manifest last (a set whose manifest exists
// is complete).
#include <cmath>
#include <cstdio>
#include <filesystem>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "io/recording_set_internal.h"

namespace fluxcal::io {
namespace {

namespace fs = std::filesystem;

std::string Fmt(double v) { return absl::StrFormat("%.10g", v); }
std::string FmtOpt(const std::optional<double>& v) { return v ? Fmt(*v) : std::string(); }

}  // namespace

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
    if (!internal::IsSafeRelativePath(m.points[k].file)) {
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
  return WriteFileAtomically((root / "manifest.json").string(), internal::ManifestToJson(m).dump(2) + "\n");
}

}  // namespace fluxcal::io
