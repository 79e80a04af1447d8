#include "tables/export_rule.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace fluxcal::tables {
namespace {

// "--udc-v" or "udc_v": how the caller names an input.
std::string Name(const ExportRequest& r, const char* field) {
  if (!r.names_flags) return field;
  std::string flag = absl::StrCat("--", field);
  for (auto& c : flag) c = c == '_' ? '-' : c;
  return flag;
}

std::string Label(const ExportRequest& r, const char* field) {
  return r.names_flags ? absl::StrCat("flag ", Name(r, field)) : Name(r, field);
}

}  // namespace

absl::StatusOr<ExportLimits> ResolveExportLimits(const fit::Calibration& cal, const std::string& kind,
                                                 const ExportRequest& req) {
  if (kind != "mtpa" && kind != "mtpv" && kind != "fw") {
    return absl::InvalidArgumentError(absl::StrCat(req.names_flags ? "flag --table" : "table",
                                                   ": expected mtpa, mtpv or fw, got '", kind, "'"));
  }
  struct Check {
    const char* field;
    const std::optional<double>& v;
    double hi;
    bool zero_ok;
  };
  for (const Check& c : {Check{"i_max_a", req.i_max_a, 1e4, false}, Check{"udc_v", req.udc_v, 5000, false},
                         Check{"rs_ohm", req.rs_ohm, 1e3, true}}) {
    if (c.v && !(std::isfinite(*c.v) && (c.zero_ok ? *c.v >= 0 : *c.v > 0) && *c.v <= c.hi)) {
      return absl::InvalidArgumentError(
          absl::StrFormat("%s: must be in %s0, %g]", Label(req, c.field), c.zero_ok ? "[" : "(", c.hi));
    }
  }
  ExportLimits out;
  MachineLimits& lim = out.limits;
  lim.pole_pairs = cal.pole_pairs();
  std::vector<std::string> overridden;
  // Current limit: the request's, else what the measurements cover, so that
  // a table does not rest on extrapolated magnetics unless asked to.
  if (req.i_max_a) {
    lim.i_max_a = *req.i_max_a;
    out.i_max_source = Name(req, "i_max_a");
  } else if (cal.MeasuredCurrentLimitA() > 0) {
    lim.i_max_a = cal.MeasuredCurrentLimitA();
    out.i_max_source = "the calibration's measured current limit";
  } else {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: the calibration's measured region (id %.4g .. %.4g A, |iq| %.4g .. %.4g A) holds no current circle "
        "(it needs id < 0 and iq > 0); give the current limit",
        Label(req, "i_max_a"), cal.id_min_a(), cal.id_max_a(), cal.iq_min_a(), cal.iq_max_a()));
  }
  // Udc and Rs: the request's, else the calibration's.
  const bool needs_udc = kind != "mtpa", needs_rs = kind == "fw";
  auto take = [&](const char* field, const std::optional<double>& given, const std::optional<double>& known,
                  const char* unit, std::optional<double>* dst, std::string* source) {
    if (given) {
      *dst = given;
      *source = Name(req, field);
      if (known && std::abs(*known - *given) > 1e-9 * std::abs(*known)) {
        overridden.push_back(absl::StrFormat("%s %g %s replaces the calibration's %g %s", Name(req, field), *given,
                                             unit, *known, unit));
      }
    } else if (known) {
      *dst = known;
      *source = "the calibration";
    }
  };
  take("udc_v", req.udc_v, cal.udc_v(), "V", &lim.udc_v, &out.udc_source);
  take("rs_ohm", req.rs_ohm, cal.rs_ohm(), "ohm", &lim.rs_ohm, &out.rs_source);
  if (needs_udc && !lim.udc_v) {
    return absl::InvalidArgumentError(absl::StrCat(
        Label(req, "udc_v"), ": the ", kind, " table is computed for a voltage limit and the calibration states no "
        "DC-link voltage (its data came without drive.udc_v); give the drive's Udc, V"));
  }
  if (needs_rs && !lim.rs_ohm) {
    return absl::InvalidArgumentError(absl::StrCat(
        Label(req, "rs_ohm"), ": the fw table needs the steady-state voltage u = Rs i + w J psi and the calibration "
        "states no Rs (its data came without motor.rs_ohm); give the stator resistance, ohm"));
  }
  for (const auto& o : overridden) out.overridden += (out.overridden.empty() ? "" : "; ") + o;
  return out;
}

absl::StatusOr<BuiltExport> BuildExportTable(const fit::Calibration& cal, TableSpec spec,
                                             const ExportRequest& req) {
  auto limits = ResolveExportLimits(cal, spec.kind, req);
  if (!limits.ok()) return limits.status();
  if (spec.serial.empty()) spec.serial = cal.serial();
  if (spec.calibration_version == 0) spec.calibration_version = cal.version;
  if (spec.model.empty()) spec.model = cal.family().Name();
  spec.measured_current_limit_a = cal.MeasuredCurrentLimitA();
  auto t = BuildTable(cal, limits->limits, spec);
  if (!t.ok()) return t.status();
  BuiltExport out;
  out.clamped = SummariseClamped(*t);
  if (out.clamped.share > kMaxClampedShare && !req.allow_clamped) {
    const auto& c = out.clamped;
    std::string check;
    const auto& lim = limits->limits;
    if (spec.kind == "fw") {
      check = absl::StrFormat("check Udc (%g V, from %s) and %s against the machine", lim.udc_v.value_or(0.0),
                              limits->udc_source, Name(req, "speed_max_rpm"));
    } else {
      check = absl::StrFormat("check the current limit (%g A, from %s)", lim.i_max_a, limits->i_max_source);
    }
    return absl::FailedPreconditionError(absl::StrFormat(
        "table %s: %zu of %zu cells (%.1f %%) clamped, more than %.0f %%: %s; %s, or give %s to export it anyway",
        spec.kind, c.clamped, c.cells, 100 * c.share, 100 * kMaxClampedShare, c.why, check,
        Name(req, "allow_clamped")));
  }
  out.table = std::move(*t);
  out.limits = std::move(*limits);
  return out;
}

}  // namespace fluxcal::tables
