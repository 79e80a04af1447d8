// BuildReport: the report page assembled. Works out once what every
// section reads (limits by the export rule, the tables, the base speed,
// the measured region; PageContext), then writes the sections in order
// (report/internal.h names where each is) and wraps them in the page.
#include "report/report.h"

#include <algorithm>
#include <cmath>
#include <map>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "physics/speed.h"
#include "report/format.h"
#include "report/internal.h"
#include "tables/export_rule.h"
#include "tables/tables.h"

namespace fluxcal::report {
namespace {

using internal::Page;
using internal::PageContext;

double SpeedRpm(double we_rad_s, int pole_pairs) { return physics::ElectricalRadSToRpm(we_rad_s, pole_pairs); }

// The limits by the export rule (tables/export_rule.h), so the checksums on
// the page are the ones an export with the same Udc prints. Udc: the
// caller's (--udc-v, a set's manifest), else the calibration's; none is
// ever assumed.
absl::Status ResolveLimits(PageContext* ctx) {
  const ReportInputs& in = *ctx->in;
  const fit::Calibration& cal = *ctx->cal;
  if (!(cal.MeasuredCurrentLimitA() > 0)) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "%s: the measured region (id %.4g .. %.4g A, |iq| %.4g .. %.4g A) holds no current circle: the page's tables "
        "need a current limit (fluxcal export --i-max-a builds them)",
        in.calibration_path, cal.id_min_a(), cal.id_max_a(), cal.iq_min_a(), cal.iq_max_a()));
  }
  tables::ExportRequest request;
  request.udc_v = in.udc_v;
  auto resolved = tables::ResolveExportLimits(cal, "mtpa", request);
  if (!resolved.ok()) {
    return absl::InvalidArgumentError(absl::StrCat(in.calibration_path, ": ", resolved.status().message()));
  }
  ctx->lim = resolved->limits;
  ctx->i_max_source = resolved->i_max_source;
  ctx->udc_source = in.udc_v ? in.udc_source : "the calibration (drive.udc_v of the set it was fitted from)";
  ctx->cov = internal::MeasuredCoverage(cal, in.identified);
  // The voltage limit needs Udc and Rs; without either the page says so
  // instead of drawing one at some default.
  const tables::MachineLimits& lim = ctx->lim;
  ctx->voltage = lim.HasVoltageLimit();
  if (!ctx->voltage) {
    ctx->no_voltage = absl::StrCat(
        "The voltage limit and the field-weakening map cannot be drawn: ",
        !lim.udc_v ? "the DC-link voltage Udc is not known (give --udc-v, or --set with a manifest that has "
                     "drive.udc_v)"
                   : "",
        !lim.udc_v && !lim.rs_ohm ? ", and " : "",
        !lim.rs_ohm ? "the calibration states no stator resistance Rs (its set's manifest has no motor.rs_ohm)" : "",
        ".");
  }
  return absl::OkStatus();
}

// The mtpa, mtpv and (with a voltage limit) fw tables the page draws and
// checksums.
absl::Status BuildTables(PageContext* ctx) {
  const ReportInputs& in = *ctx->in;
  const fit::Calibration& cal = *ctx->cal;
  tables::TableSpec& spec = ctx->spec;
  spec.serial = cal.serial();
  spec.calibration_version = cal.version;
  spec.model = cal.family().Name();
  spec.measured_current_limit_a = cal.MeasuredCurrentLimitA();
  for (const char* kind : {"mtpa", "mtpv", "fw"}) {
    if (std::string(kind) == "fw" && !ctx->voltage) continue;
    spec.kind = kind;
    spec.allow_extrapolation = false;
    auto t = tables::BuildTable(cal, ctx->lim, spec);
    if (!t.ok() && std::string(kind) == "mtpv" && absl::IsFailedPrecondition(t.status())) {
      // No MTPV point inside the measured current limit: the export refuses
      // it; the page still draws it, computed in extrapolated magnetics and
      // said so (cells flagged, as `export --allow-extrapolation` would).
      spec.allow_extrapolation = true;
      t = tables::BuildTable(cal, ctx->lim, spec);
      ctx->mtpv_extrapolated = true;
      ctx->mtpv_note = std::string(
          "The MTPV curve lies beyond the measured current limit: drawn from the calibration's continuation "
          "(extrapolated, dotted); `fluxcal export --table mtpv` refuses it without --allow-extrapolation.");
    }
    if (!t.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(in.calibration_path, ": ", kind, " table: ", t.status().message()));
    }
    ctx->tabs[kind] = std::move(*t);
  }
  return absl::OkStatus();
}

// Base speed: where the MTPA point of the largest motoring torque meets
// the voltage limit (bisection; the voltage grows with speed there); the
// speed the voltage limit is drawn at; a warning when the limits are not
// the machine's.
void Speeds(PageContext* ctx) {
  const ReportInputs& in = *ctx->in;
  const fit::Calibration& cal = *ctx->cal;
  const tables::MachineLimits& lim = ctx->lim;
  const auto& mtpa = ctx->tabs.at("mtpa");
  size_t kmax = 0;
  for (size_t k = 0; k < mtpa.axes[0].values.size(); ++k) {
    if (mtpa.axes[0].values[k] > mtpa.axes[0].values[kmax]) kmax = k;
  }
  const double id_b = mtpa.outputs[0].values[kmax], iq_b = mtpa.outputs[1].values[kmax];
  if (ctx->voltage) {
    double we_lo = 0, we_hi = 1e6;
    if (tables::VoltageV(cal, lim, id_b, iq_b, we_hi) < lim.UMaxV()) we_lo = we_hi;
    for (int k = 0; k < 80 && we_lo < we_hi; ++k) {
      const double mid = 0.5 * (we_lo + we_hi);
      (tables::VoltageV(cal, lim, id_b, iq_b, mid) < lim.UMaxV() ? we_lo : we_hi) = mid;
    }
    ctx->base_rpm = SpeedRpm(we_lo, lim.pole_pairs);
    ctx->ell_rpm = in.ellipse_speed_rpm;
    ctx->ell_source = "given (--speed-rpm)";
    if (!(ctx->ell_rpm > 0)) {
      // 1.5 x base speed, to two significant digits: far enough into field
      // weakening that the limit cuts the current circle.
      const double raw = 1.5 * ctx->base_rpm;
      const double mag = std::pow(10.0, std::floor(std::log10(std::max(raw, 1.0))) - 1);
      ctx->ell_rpm = std::round(raw / mag) * mag;
      ctx->ell_source = absl::StrFormat("1.5 x base speed %s, rounded", Num(ctx->base_rpm, kSpeedRpm, "rpm"));
    }
    // At standstill the voltage is Rs |i|: when that alone exceeds u_max the
    // limits are not the machine's (a wrong Udc) and the field-weakening map
    // is clamped everywhere. Said at the top.
    const double standstill_v = tables::VoltageV(cal, lim, id_b, iq_b, 0.0);
    if (!(ctx->base_rpm > 0) || standstill_v >= lim.UMaxV()) {
      ctx->limits_warning = absl::StrFormat(
          "The voltage limit u_max = %s (Udc %s: %s) is below the resistive drop at full MTPA current "
          "(%s at standstill): there is no base speed, and the field-weakening table is clamped at every "
          "speed. Check the machine's DC-link voltage (--udc-v, or a set whose manifest has drive.udc_v).",
          Num(lim.UMaxV(), kVoltageV, "V"), Num(*lim.udc_v, kVoltageV, "V"), ctx->udc_source,
          Num(standstill_v, kVoltageV, "V"));
    }
  }
  ctx->ell_we = physics::RpmToElectricalRadS(ctx->ell_rpm, lim.pole_pairs);
}

// The page's style sheet.
constexpr char kCss[] = R"css(
body{font-family:sans-serif;margin:24px;color:#222;max-width:1360px}
h1{font-size:22px;margin:0 0 8px} h1 .ver{font-weight:normal;color:#666;font-size:16px}
h2{font-size:17px;border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:28px} h3{font-size:14px}
.verdict{display:inline-block;padding:4px 12px;border-radius:4px;font-weight:bold;color:#fff}
.verdict.pass{background:#2a7d2a} .verdict.fail{background:#b02a2a}
table{border-collapse:collapse;font-size:13px} th,td{text-align:left;padding:3px 8px;vertical-align:top}
table.kv th{color:#555;font-weight:normal;white-space:nowrap} table.kv td{max-width:1000px}
table.list{margin:6px 0} table.list th{background:#f0f0f0} table.list td,table.list th{border:1px solid #ddd}
tr.selected td{font-weight:bold}
code.sha{font-size:11px;word-break:break-all}
.grid{display:grid;grid-template-columns:repeat(2,max-content);gap:12px}
ul.excluded{font-size:13px}
figure{margin:8px 0;border:1px solid #e0e0e0;padding:6px;background:#fff}
figure svg{display:block}
figcaption{font-size:12px;color:#555;max-width:640px;margin-top:4px}
small,.note{color:#666;font-size:12px}
.warn{background:#fff3cd;border:1px solid #e0c060;padding:8px 12px;font-size:13px;max-width:1000px}
)css";

}  // namespace

absl::StatusOr<Report> BuildReport(const ReportInputs& in) {
  if (in.calibration == nullptr) return absl::InvalidArgumentError("calibration: missing");
  const fit::Calibration& cal = *in.calibration;
  if (in.diagnosis && in.diagnosis->value("format", "") != "fluxcal.diagnosis.v1") {
    return absl::InvalidArgumentError(
        absl::StrCat(in.diagnosis_path, ": field 'format': expected 'fluxcal.diagnosis.v1'"));
  }
  PageContext ctx;
  ctx.in = &in;
  ctx.cal = &cal;
  if (absl::Status s = ResolveLimits(&ctx); !s.ok()) return s;
  if (absl::Status s = BuildTables(&ctx); !s.ok()) return s;
  Speeds(&ctx);
  ctx.pd = internal::ScanPositiveDefinite(cal, ctx.cov);

  Page page;
  internal::IdentitySection(ctx, &page);
  internal::FitSection(ctx, &page);
  internal::SurfacesSection(ctx, &page);
  internal::CurrentPlaneSection(ctx, &page);
  auto env = internal::BuildEnvelope(ctx);
  if (!env.ok()) return env.status();
  internal::EnvelopeSection(ctx, *env, &page);
  internal::FieldWeakeningSection(ctx, *env, &page);
  internal::TablesSection(ctx, &page);
  internal::FleetSection(ctx, &page);
  internal::DiagnosisSection(ctx, &page);

  Report rep;
  rep.ellipse_speed_rpm = ctx.ell_rpm;
  rep.figures = page.figures;
  rep.html = "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>fluxcal report " +
             internal::H(cal.serial()) + absl::StrFormat(" v%d", cal.version) + "</title>\n<style>" + kCss +
             "</style></head>\n<body>\n" + page.body + "</body></html>\n";
  return rep;
}

}  // namespace fluxcal::report
