#include "tables/export_rule.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/strings/ascii.h"

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
  if (kind != "mtpa" && kind != "mtpv" && kind != "fw" && kind != "envelope") {
    return absl::InvalidArgumentError(absl::StrCat(req.names_flags ? "flag --table" : "table",
                                                   ": expected mtpa, mtpv, fw or envelope, got '", kind, "'"));
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
  const bool needs_udc = kind != "mtpa", needs_rs = kind == "fw" || kind == "envelope";
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
        Label(req, "rs_ohm"), ": the ", kind, " table needs the steady-state voltage u = Rs i + w J psi and the calibration "
        "states no Rs (its data came without motor.rs_ohm); give the stator resistance, ohm"));
  }
  for (const auto& o : overridden) out.overridden += (out.overridden.empty() ? "" : "; ") + o;
  return out;
}

absl::Status CheckExportSpec(const TableSpec& spec, const ExportRequest& req) {
  // An unknown kind is ResolveExportLimits' to name.
  const bool known = spec.kind == "mtpa" || spec.kind == "mtpv" || spec.kind == "fw";
  if (spec.envelope_generating && known) {
    return absl::InvalidArgumentError(absl::StrCat(
        Label(req, "generating"), ": only with ", Name(req, "table"), " envelope (the generating torque-speed "
        "limit), not with ", Name(req, "table"), " ", spec.kind, spec.kind == "mtpv" ? " (motoring rows)" :
        spec.kind == "mtpa" || spec.kind == "fw" ? " (it holds the generating rows already)" : ""));
  }
  return absl::OkStatus();
}

absl::StatusOr<BuiltExport> BuildExportTable(const fit::Calibration& cal, TableSpec spec,
                                             const ExportRequest& req) {
  if (auto s = CheckExportSpec(spec, req); !s.ok()) return s;
  auto limits = ResolveExportLimits(cal, spec.kind, req);
  if (!limits.ok()) return limits.status();
  if (spec.serial.empty()) spec.serial = cal.serial();
  if (spec.calibration_version == 0) spec.calibration_version = cal.version;
  if (spec.model.empty()) spec.model = cal.family().Name();
  spec.measured_current_limit_a = cal.MeasuredCurrentLimitA();
  if (req.magnet_temp_c) {
    auto mt = MagnetTemperatureOf(cal, *req.magnet_temp_c, req);
    if (!mt.ok()) return mt.status();
    spec.magnet_temperature = *mt;
  }
  auto t = BuildTable(cal, limits->limits, spec);
  if (!t.ok()) return t.status();
  BuiltExport out;
  out.clamped = SummariseClamped(*t);
  if (out.clamped.share > kMaxClampedShare && !req.allow_clamped) {
    const auto& c = out.clamped;
    std::string check;
    const auto& lim = limits->limits;
    if (spec.kind == "fw" || spec.kind == "envelope") {
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

absl::StatusOr<MagnetTemperature> MagnetTemperatureOf(const fit::Calibration& cal, double at_c,
                                                      const ExportRequest& req) {
  if (!std::isfinite(at_c) || at_c < -60 || at_c > 250) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: %g degC is no magnet temperature (-60 .. 250 degC)", Label(req, "magnet_temp_c"), at_c));
  }
  // The calibration's own coefficient and the magnet temperature of its
  // flux map (fit::Calibration, docs/fitting.md); neither is assumed.
  const std::optional<double>& alpha = cal.psi_pm_temp_coeff_per_k();
  const std::optional<double>& ref = cal.magnet_reference_c();
  if (alpha && ref) {
    MagnetTemperature mt;
    mt.alpha_per_k = *alpha;
    mt.reference_c = *ref;
    mt.at_c = at_c;
    mt.reference_spread_k = cal.magnet_reference_spread_k();
    return mt;
  }
  std::vector<std::string> missing;
  if (!alpha) {
    missing.push_back("no magnet temperature coefficient (its data stated no motor.psi_pm_temp_coeff_per_k; "
                      "`fluxcal fit --magnet-temp-coeff-per-k` states it)");
  }
  if (!ref) {
    missing.push_back("no magnet temperature of its flux map (not every observation its fit used recorded a "
                      "temperature_c; `fluxcal fit --magnet-reference-c` states it for data that record none)");
  }
  return absl::InvalidArgumentError(absl::StrFormat(
      "%s: the calibration of %s states %s, so a table at %g degC would rest on an assumed one (NdFeB is about "
      "-0.1 %%/K, but the magnet's own grade decides); export at the calibration's temperature (without %s), or "
      "fit the motor again with what is missing stated",
      Label(req, "magnet_temp_c"), cal.serial(), absl::StrJoin(missing, " and "), at_c, Name(req, "magnet_temp_c")));
}

std::string MagnetTemperatureNote(const MagnetTemperature& mt) {
  std::string s = absl::StrFormat(
      "magnets at %.4g degC: psi_pm x %.6g = 1 + alpha (T - T_ref) with the calibration's alpha %.4g /K and "
      "T_ref %.4g degC",
      mt.at_c, mt.Scale(), mt.alpha_per_k, mt.reference_c);
  if (mt.reference_spread_k && *mt.reference_spread_k > fit::kMagnetReferenceSpreadWarnK) {
    absl::StrAppendFormat(&s,
                          "; warning: the flux map was recorded over a %.3g K spread of temperatures (more than "
                          "%.3g K: a machine warming during the test), so T_ref is their mean and psi_pm(T) is "
                          "uncertain by about %.2g %%",
                          *mt.reference_spread_k, fit::kMagnetReferenceSpreadWarnK,
                          100 * std::abs(mt.alpha_per_k) * *mt.reference_spread_k / 2);
  }
  return s;
}

absl::StatusOr<std::vector<double>> ParseUdcAxis(const std::string& text, const std::string& flag) {
  std::vector<double> v;
  auto bad = [&](const std::string& why) {
    return absl::InvalidArgumentError(absl::StrCat("flag ", flag, ": '", text, "': ", why,
                                                   " (a list 250,300,350 or a range LO:HI:N, V)"));
  };
  auto num = [](absl::string_view s, double* x) { return absl::SimpleAtod(s, x) && std::isfinite(*x); };
  if (text.find(':') != std::string::npos) {
    std::vector<absl::string_view> p = absl::StrSplit(text, ':');
    double lo, hi;
    int n;
    if (p.size() != 3 || !num(p[0], &lo) || !num(p[1], &hi) || !absl::SimpleAtoi(p[2], &n)) {
      return bad("expected LO:HI:N");
    }
    if (n < 2 || n > kMaxUdcAxisPoints || !(hi > lo)) {
      return bad(absl::StrFormat("a range needs LO < HI and 2 <= N <= %d", kMaxUdcAxisPoints));
    }
    for (int k = 0; k < n; ++k) v.push_back(k == n - 1 ? hi : lo + (hi - lo) * k / (n - 1));
  } else {
    for (absl::string_view s : absl::StrSplit(text, ',')) {
      double x;
      if (!num(absl::StripAsciiWhitespace(s), &x)) return bad(absl::StrCat("'", s, "' is not a number"));
      v.push_back(x);
    }
  }
  if (v.size() > static_cast<size_t>(kMaxUdcAxisPoints)) {
    return bad(absl::StrFormat("at most %d voltages", kMaxUdcAxisPoints));
  }
  for (size_t k = 0; k < v.size(); ++k) {
    if (!(v[k] > 0 && v[k] <= 5000)) return bad(absl::StrFormat("%g V is not in (0, 5000] V", v[k]));
    if (k > 0 && !(v[k] > v[k - 1])) return bad("the voltages must increase");
    if (k > 0 && UdcTag(v[k]) == UdcTag(v[k - 1])) {
      return bad(absl::StrFormat("%s and %s have the same label (%s)", absl::StrFormat("%.17g", v[k - 1]),
                                 absl::StrFormat("%.17g", v[k]), UdcTag(v[k])));
    }
  }
  return v;
}

absl::StatusOr<std::vector<BuiltExport>> BuildExportTablesOverUdc(const fit::Calibration& cal, const TableSpec& spec,
                                                                  const ExportRequest& req,
                                                                  const std::vector<double>& udcs) {
  if (req.udc_v) {
    return absl::InvalidArgumentError(absl::StrCat(Label(req, "udc_v"), ": give one Udc or a Udc axis (",
                                                   Name(req, "udc_axis_v"), "), not both"));
  }
  if (udcs.empty()) return absl::InvalidArgumentError(absl::StrCat(Label(req, "udc_axis_v"), ": no voltage"));
  // The axis as ParseUdcAxis accepts it: a caller that built it otherwise
  // must not get two tables under one label.
  for (size_t k = 0; k < udcs.size(); ++k) {
    if (!(udcs[k] > 0 && udcs[k] <= 5000) || (k > 0 && !(udcs[k] > udcs[k - 1])) ||
        (k > 0 && UdcTag(udcs[k]) == UdcTag(udcs[k - 1])) || k >= static_cast<size_t>(kMaxUdcAxisPoints)) {
      return absl::InvalidArgumentError(absl::StrFormat(
          "%s: at most %d voltages in (0, 5000] V, increasing, each with its own label (%g V at position %zu)",
          Label(req, "udc_axis_v"), kMaxUdcAxisPoints, udcs[k], k + 1));
    }
  }
  std::vector<BuiltExport> out;
  for (double u : udcs) {
    ExportRequest r = req;
    r.udc_v = u;
    TableSpec s = spec;
    s.label_tag = UdcTag(u);
    auto b = BuildExportTable(cal, s, r);
    if (!b.ok()) {
      // The voltage after the message, so that a refusal naming a flag
      // still starts with it (the CLI's exit code rule).
      return absl::Status(b.status().code(), absl::StrFormat("%s (at Udc %g V of %s)", b.status().message(), u,
                                                             Name(req, "udc_axis_v")));
    }
    out.push_back(*std::move(b));
  }
  return out;
}

}  // namespace fluxcal::tables
