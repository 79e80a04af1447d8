#include "report/report.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <map>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "plot/plot.h"
#include "tables/tables.h"

namespace fluxcal::report {
namespace {

constexpr double kPi = 3.14159265358979323846;

std::string H(const std::string& s) { return plot::Escape(s); }   // HTML text escape

std::string NowUtc() {
  std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  char b[32];
  std::strftime(b, sizeof b, "%Y-%m-%dT%H:%M:%SZ", &tm);
  return b;
}

std::vector<double> Linspace(double a, double b, int n) {
  std::vector<double> v(n);
  for (int k = 0; k < n; ++k) v[k] = n == 1 ? a : a + (b - a) * k / (n - 1);
  return v;
}

// A JSON value as text: strings unquoted, numbers to four significant
// digits (a residual of 0.340434522398985 reads as 0.3404), "" when absent.
std::string ValueText(const nlohmann::json& v) {
  if (v.is_null()) return "";
  if (v.is_string()) return v.get<std::string>();
  if (v.is_number_float()) return absl::StrFormat("%.4g", v.get<double>());
  return v.dump();
}
std::string JsonText(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key)) return "";
  return ValueText(j[key]);
}

std::string Row(const std::string& k, const std::string& v) {
  return "<tr><th>" + H(k) + "</th><td>" + v + "</td></tr>\n";
}

// The family of currents to draw curves for (id values, or iq values when
// `over_id`): the identified points' own set points when there are points
// (so dots and lines pair up; measured currents scatter around the set
// point, so values closer than 3 % of the range are one group), otherwise
// round values across the measured range. At most six.
std::vector<double> Family(const fit::Calibration& cal, const fit::FitData* data, bool over_id) {
  const double lo = over_id ? std::min(0.0, cal.iq_min_a()) : cal.id_min_a();
  const double hi = over_id ? cal.iq_max_a() : cal.id_max_a();
  std::vector<double> v;
  if (data != nullptr && !data->inductances.empty()) {
    std::vector<double> raw;
    for (const auto& o : data->inductances) raw.push_back(over_id ? o.iq_a : o.id_a);
    std::sort(raw.begin(), raw.end());
    const double tol = std::max(1.0, 0.03 * (hi - lo));
    size_t start = 0;
    for (size_t k = 1; k <= raw.size(); ++k) {
      if (k == raw.size() || raw[k] - raw[k - 1] > tol) {
        double sum = 0;
        for (size_t m = start; m < k; ++m) sum += raw[m];
        const double c = std::round(sum / (k - start));
        v.push_back(c == 0 ? 0.0 : c);   // no "-0 A" in a legend
        start = k;
      }
    }
  }
  if (v.empty()) {
    for (double t : plot::NiceTicks(lo, hi, 5)) {
      if (t >= lo - 1e-9 && t <= hi + 1e-9) v.push_back(t);
    }
    if (v.empty()) v = {lo, hi};
  }
  if (v.size() > 6) {
    std::vector<double> pick;
    for (int k = 0; k < 6; ++k) pick.push_back(v[k * (v.size() - 1) / 5]);
    v = pick;
  }
  return v;
}

// Index of the family member an observed current belongs to, -1 if none
// (closer than half the smallest spacing, or 3 % of the range for one).
int Member(const std::vector<double>& family, double value, double range) {
  double spacing = range;
  for (size_t k = 1; k < family.size(); ++k) spacing = std::min(spacing, family[k] - family[k - 1]);
  const double tol = family.size() > 1 ? spacing / 2 : 0.03 * range;
  int best = -1;
  for (size_t k = 0; k < family.size(); ++k) {
    if (std::abs(value - family[k]) <= tol && (best < 0 || std::abs(value - family[k]) < std::abs(value - family[best]))) {
      best = static_cast<int>(k);
    }
  }
  return best;
}

struct Page {
  std::string body;
  int figures = 0;
  void Figure(const plot::Figure& f, const std::string& caption) {
    body += "<figure>" + f.Svg() + "<figcaption>" + caption + "</figcaption></figure>\n";
    ++figures;
  }
};

// Differential inductance or flux linkage against iq, one curve per id
// (psi_d against id, one curve per iq: its shape along id is the d-axis
// saturation); the identified inductances (with +-1 sigma) in the colour
// of their curve.
enum class Quantity { kLdd, kLqq, kLdq, kPsiD, kPsiQ };

void QuantityFigure(Page* page, const fit::Calibration& cal, const fit::FitData* data, Quantity q) {
  const bool over_id = q == Quantity::kPsiD;   // x axis id, curves per iq
  const std::vector<double> fam = Family(cal, data, over_id);
  const double x_lo = over_id ? cal.id_min_a() : std::min(0.0, cal.iq_min_a());
  const double x_hi = over_id ? cal.id_max_a() : cal.iq_max_a();
  const auto xs = Linspace(x_lo, x_hi, 81);
  struct Spec { const char* id; const char* title; const char* ylabel; };
  const Spec spec[] = {{"ldd", "Ldd = dpsi_d/did", "Ldd [mH]"},
                       {"lqq", "Lqq = dpsi_q/diq", "Lqq [mH]"},
                       {"ldq", "Ldq = dpsi_d/diq (cross saturation)", "Ldq [mH]"},
                       {"psid", "flux linkage psi_d", "psi_d [mWb]"},
                       {"psiq", "flux linkage psi_q", "psi_q [mWb]"}};
  const Spec& sp = spec[static_cast<int>(q)];
  plot::Figure f(std::string("fig-") + sp.id, 640, 340);
  f.SetTitle(sp.title);
  f.SetXLabel(over_id ? "id [A]" : "iq [A]");
  f.SetYLabel(sp.ylabel);
  f.SetXRange(x_lo, x_hi);
  // The frame ends where the surface's region ends (e.g. id 0.16 A): a
  // whole-tick end would leave a band with nothing in it.
  f.SetTight(true, false);
  auto value = [&](const fit::FluxPrediction& p) {
    switch (q) {
      case Quantity::kLdd: return p.ldd_h;
      case Quantity::kLqq: return p.lqq_h;
      case Quantity::kLdq: return p.ldq_h;
      case Quantity::kPsiD: return p.psi_d_wb;
      case Quantity::kPsiQ: return p.psi_q_wb;
    }
    return 0.0;
  };
  // Everything in mH / mWb: the values engineers quote.
  constexpr double kMilli = 1e3;
  std::vector<std::vector<double>> px(fam.size()), py(fam.size()), pe(fam.size());
  size_t drawn_points = 0;
  if (data != nullptr && q != Quantity::kPsiD && q != Quantity::kPsiQ) {
    for (const auto& o : data->inductances) {
      const int k = Member(fam, o.id_a, cal.id_max_a() - cal.id_min_a());
      if (k < 0) continue;
      double v = 0, e = 0;
      if (q == Quantity::kLdd) v = o.ldd_h, e = o.ldd_h_std;
      if (q == Quantity::kLqq) v = o.lqq_h, e = o.lqq_h_std;
      if (q == Quantity::kLdq) {
        if (!o.ldq_h) continue;
        v = *o.ldq_h, e = o.ldq_h_std;
      }
      px[k].push_back(o.iq_a);
      py[k].push_back(kMilli * v);
      pe[k].push_back(kMilli * e);
      ++drawn_points;
    }
  }
  for (size_t k = 0; k < fam.size(); ++k) {
    plot::Style st;
    st.colour = plot::Palette(static_cast<int>(k));
    std::vector<double> y;
    for (double x : xs) y.push_back(kMilli * value(over_id ? cal.Predict(x, fam[k]) : cal.Predict(fam[k], x)));
    f.Line(xs, y, st, absl::StrFormat("%s = %g A", over_id ? "iq" : "id", fam[k]));
    if (!px[k].empty()) f.Scatter(px[k], py[k], st, "", pe[k]);
  }
  if (drawn_points > 0) {
    plot::Style grey;
    grey.colour = "#555";
    f.Scatter({}, {}, grey, "identified, +-1 sigma");
  }
  page->Figure(f, absl::StrFormat("%s of %s from the fitted surface, one line per %s%s.", sp.title, H(cal.serial()),
                                  over_id ? "iq" : "id",
                                  drawn_points > 0
                                      ? absl::StrFormat("; dots: %zu identified points in the colour of their id", drawn_points)
                                      : ""));
}

double SpeedRpm(double we_rad_s, int pole_pairs) { return we_rad_s / pole_pairs * 60 / (2 * kPi); }

}  // namespace

absl::StatusOr<Report> BuildReport(const ReportInputs& in) {
  if (in.calibration == nullptr) return absl::InvalidArgumentError("calibration: missing");
  const fit::Calibration& cal = *in.calibration;
  if (in.diagnosis && in.diagnosis->value("format", "") != "fluxcal.diagnosis.v1") {
    return absl::InvalidArgumentError(
        absl::StrCat(in.diagnosis_path, ": field 'format': expected 'fluxcal.diagnosis.v1'"));
  }
  Report rep;
  Page page;

  // Limits as `fluxcal export` sets them, so the checksums on this page are
  // the ones an export with the same flags prints.
  tables::MachineLimits lim;
  lim.pole_pairs = cal.pole_pairs();
  lim.rs_ohm = cal.rs_ohm();
  std::string i_max_source = "fluxcal export default (the calibration has no measured region)";
  if (cal.MeasuredCurrentLimitA() > 0) {
    lim.i_max_a = cal.MeasuredCurrentLimitA();
    i_max_source = "largest current circle inside the measured region";
  }
  std::string udc_source = "fluxcal export default (no recording set or --udc-v given)";
  if (in.udc_v) {
    lim.udc_v = *in.udc_v;
    udc_source = in.udc_source;
  }
  tables::TableSpec spec;
  spec.serial = cal.serial();
  spec.calibration_version = cal.version;
  spec.model = cal.family().Name();
  spec.measured_current_limit_a = cal.MeasuredCurrentLimitA();
  std::map<std::string, tables::Table> tabs;
  std::string mtpv_note;
  for (const char* kind : {"mtpa", "mtpv", "fw"}) {
    spec.kind = kind;
    spec.allow_extrapolation = false;
    auto t = tables::BuildTable(cal, lim, spec);
    if (!t.ok() && std::string(kind) == "mtpv" && absl::IsFailedPrecondition(t.status())) {
      // No MTPV point inside the measured current limit: the export refuses
      // it; the page still draws it, computed in extrapolated magnetics and
      // said so (cells flagged, as `export --allow-extrapolation` would).
      spec.allow_extrapolation = true;
      t = tables::BuildTable(cal, lim, spec);
      mtpv_note = std::string(
          "The MTPV curve lies beyond the measured current limit: drawn from the calibration's continuation "
          "(extrapolated); `fluxcal export --table mtpv` refuses it without --allow-extrapolation.");
    }
    if (!t.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(in.calibration_path, ": ", kind, " table: ", t.status().message()));
    }
    tabs[kind] = std::move(*t);
  }
  const auto& mtpa = tabs["mtpa"];
  const auto& mtpv = tabs["mtpv"];
  const auto& fw = tabs["fw"];

  // Base speed: where the MTPA point of the largest motoring torque meets
  // the voltage limit (bisection; the voltage grows with speed there).
  size_t kmax = 0;
  for (size_t k = 0; k < mtpa.axes[0].values.size(); ++k) {
    if (mtpa.axes[0].values[k] > mtpa.axes[0].values[kmax]) kmax = k;
  }
  const double id_b = mtpa.outputs[0].values[kmax], iq_b = mtpa.outputs[1].values[kmax];
  double we_lo = 0, we_hi = 1e6;
  if (tables::VoltageV(cal, lim, id_b, iq_b, we_hi) < lim.UMaxV()) we_lo = we_hi;
  for (int k = 0; k < 80 && we_lo < we_hi; ++k) {
    const double mid = 0.5 * (we_lo + we_hi);
    (tables::VoltageV(cal, lim, id_b, iq_b, mid) < lim.UMaxV() ? we_lo : we_hi) = mid;
  }
  const double base_rpm = SpeedRpm(we_lo, lim.pole_pairs);
  double ell_rpm = in.ellipse_speed_rpm;
  std::string ell_source = "given (--speed-rpm)";
  if (!(ell_rpm > 0)) {
    // 1.5 x base speed, to two significant digits: far enough into field
    // weakening that the limit cuts the current circle.
    const double raw = 1.5 * base_rpm;
    const double mag = std::pow(10.0, std::floor(std::log10(std::max(raw, 1.0))) - 1);
    ell_rpm = std::round(raw / mag) * mag;
    ell_source = absl::StrFormat("1.5 x base speed %.0f rpm, rounded", base_rpm);
  }
  rep.ellipse_speed_rpm = ell_rpm;
  // At standstill the voltage is Rs |i|: when that alone exceeds u_max the
  // limits are not the machine's (usually Udc left at the export default)
  // and the field-weakening map is clamped everywhere. Said at the top.
  const double standstill_v = tables::VoltageV(cal, lim, id_b, iq_b, 0.0);
  std::string limits_warning;
  if (!(base_rpm > 0) || standstill_v >= lim.UMaxV()) {
    limits_warning = absl::StrFormat(
        "The voltage limit u_max = %.3g V (Udc %.4g V: %s) is below the resistive drop at full MTPA current "
        "(%.3g V at standstill): there is no base speed, and the field-weakening table is clamped at every "
        "speed. Give the machine's DC-link voltage (--udc-v, or a set whose manifest has drive.udc_v).",
        lim.UMaxV(), lim.udc_v, udc_source, standstill_v);
  }
  const double ell_we = ell_rpm * lim.pole_pairs * 2 * kPi / 60;

  // ------------------------------------------------------------ identity
  const nlohmann::json& cj = in.calibration_json;
  const std::string verdict = !in.verdict.empty() ? in.verdict : JsonText(cj, "verdict");
  const bool pass = verdict == "pass";
  std::string& b = page.body;
  b += absl::StrFormat("<header><h1>Calibration report: %s <span class=\"ver\">version %d</span></h1>\n", H(cal.serial()),
                       cal.version);
  b += absl::StrFormat("<div class=\"verdict %s\">%s</div></header>\n", pass ? "pass" : "fail",
                       verdict.empty() ? "no verdict" : H(verdict));
  if (!limits_warning.empty()) b += "<p class=\"warn\">" + H(limits_warning) + "</p>\n";
  b += "<section><h2>Identity and provenance</h2><table class=\"kv\">\n";
  b += Row("serial", H(cal.serial()));
  b += Row("calibration version", absl::StrCat(cal.version, cal.version == 0 ? " (not stored yet: versions are assigned by the store)" : ""));
  b += Row("model family", H(cal.family().Name()));
  b += Row("calibration from", H(in.calibration_path));
  const std::string created = JsonText(cj, "created_utc");
  b += Row("calibration created", created.empty() ? "not recorded in the file; file modified " + H(in.calibration_file_mtime_utc)
                                                  : H(created));
  const std::string sw = JsonText(cj, "software_version");
  b += Row("software that fitted it", sw.empty() ? "not recorded in the file" : H(sw));
  const std::string released = JsonText(cj, "released");
  b += Row("release state", released.empty() ? "not known from a file (the service knows: fluxcal report SERIAL --server ADDR)"
                                             : H(released));
  b += Row("recording set", in.set_path.empty() ? "not given (no identified points drawn)" : H(in.set_path));
  b += Row("verdict", (verdict.empty() ? "none" : H(verdict)) + (in.verdict_basis.empty() ? "" : " <small>(" + H(in.verdict_basis) + ")</small>"));
  b += Row("report written", H(NowUtc()) + " by fluxcal " + H(in.software_version));
  b += "</table></section>\n";

  // ------------------------------------------------------------ fit
  const auto& s = cal.summary;
  b += "<section><h2>Fit quality</h2><table class=\"kv\">\n";
  b += Row("usable", s.usable ? "yes" : "<b>no</b>");
  b += Row("termination", H(s.termination));
  b += Row("observations", absl::StrCat(s.observations));
  b += Row("RMS relative residual", absl::StrFormat("%.3f %%", 100 * s.rms_relative));
  b += Row("chi2 / BIC", absl::StrFormat("%.4g / %.4g", s.chi2, s.bic));
  b += Row("psi_pm", absl::StrFormat("%.6g Wb", cal.psi_pm_wb()));
  b += Row("Rs (nominal) / pole pairs", absl::StrFormat("%.6g ohm / %d", cal.rs_ohm(), cal.pole_pairs()));
  b += Row("measured region", absl::StrFormat("id %.4g .. %.4g A, |iq| %.4g .. %.4g A", cal.id_min_a(), cal.id_max_a(),
                                              cal.iq_min_a(), cal.iq_max_a()));
  // The half of the iq axis nothing measured: "by symmetry" when the model
  // mirrors the measured one, "extrapolated" otherwise (fit::Region).
  b += Row("iq halves", H(cal.IqRegionText()));
  b += Row("positive definite over 1.5 x region", cal.PhysicalOver(1.5) ? "yes" : "<b>no</b>");
  b += "</table>\n";
  b += absl::StrFormat("<h3>Model candidates (%zu)</h3>\n", s.candidates.size());
  if (s.candidates.empty()) {
    b += "<p>none recorded (a single model was fitted)</p>\n";
  } else {
    b += "<pre class=\"cands\">" + H(absl::StrJoin(s.candidates, "\n")) + "</pre>\n";
  }
  b += absl::StrFormat("<h3>Excluded or down-weighted observations (%zu)</h3>\n", s.excluded.size());
  if (s.excluded.empty()) {
    b += "<p>none</p>\n";
  } else {
    b += "<ul class=\"excluded\">";
    for (const auto& e : s.excluded) b += "<li>" + H(e) + "</li>";
    b += "</ul>\n";
  }
  b += "</section>\n";

  // ------------------------------------------------------------ surfaces
  b += "<section><h2>Inductances and flux linkages</h2><div class=\"grid\">\n";
  for (Quantity q : {Quantity::kLdd, Quantity::kLqq, Quantity::kLdq, Quantity::kPsiD, Quantity::kPsiQ}) {
    QuantityFigure(&page, cal, in.identified, q);
  }
  b += "</div></section>\n";

  // ------------------------------------------------------------ current plane
  b += "<section><h2>Operating limits: MTPA, MTPV, current and voltage limit</h2>\n";
  {
    const double im = lim.i_max_a;
    plot::Figure f("fig-plane", 980, 640);
    f.SetTitle(absl::StrFormat("MTPA and MTPV on the current plane (voltage limit at %.0f rpm)", ell_rpm));
    f.SetXLabel("id [A]");
    f.SetYLabel("iq [A]");
    // Wide enough for the MTPV points near the current limit (up to
    // 1.6 i_max); rows farther out are counted in the legend instead.
    double mtpv_id_min = -1.2 * im;
    for (size_t k = 0; k < mtpv.outputs[0].values.size(); ++k) {
      const double d = mtpv.outputs[0].values[k];
      if (mtpv.outputs[2].values[k] > 0 && d >= -1.6 * im) mtpv_id_min = std::min(mtpv_id_min, d);
    }
    const double view_x_lo = mtpv_id_min, view_y_hi = 1.2 * im;
    f.SetXRange(view_x_lo, 0.1 * im);
    f.SetYRange(0, 1.2 * im);
    f.SetEqualAspect(true);
    f.SetTight(true, true);
    // Torque contours, current circle and voltage limit: the same drawing
    // as the exported MTPA / MTPV figures (tables::DrawCurrentPlane).
    tables::DrawCurrentPlane(&f, cal, lim, -2.5 * im, 2.5 * im, ell_we,
                             absl::StrFormat("voltage limit |u| = %.3g V at %.0f rpm", lim.UMaxV(), ell_rpm));
    plot::Style region;
    region.colour = "#2ca02c";
    region.width_px = 1;
    region.dash = "1 3";
    f.Line({cal.id_min_a(), cal.id_max_a(), cal.id_max_a(), cal.id_min_a(), cal.id_min_a()},
           {cal.iq_min_a(), cal.iq_min_a(), cal.iq_max_a(), cal.iq_max_a(), cal.iq_min_a()}, region, "measured region");
    auto curve = [&](const tables::Table& t, const std::string& colour, std::string label) -> bool {
      std::vector<double> x, y;
      size_t beyond = 0;
      for (size_t k = 0; k < t.outputs[0].values.size(); ++k) {
        if (t.outputs[1].values[k] < 0) continue;   // motoring half only
        // MTPV rows the solver could not place (no torque, or id at its
        // search bound of -2 i_max) are not points of the curve.
        if (t.kind == "mtpv" && (!(t.outputs[2].values[k] > 0) || t.outputs[0].values[k] < -1.99 * im)) continue;
        x.push_back(t.outputs[0].values[k]);
        y.push_back(t.outputs[1].values[k]);
        if (x.back() < view_x_lo || y.back() > view_y_hi) ++beyond;
      }
      if (x.empty()) return false;   // nothing to draw: the caption says so
      if (beyond > 0) label += absl::StrFormat(", %zu of %zu points beyond the view", beyond, x.size());
      plot::Style st;
      st.colour = colour;
      st.width_px = 2.5;
      f.Line(x, y, st, label);
      return true;
    };
    curve(mtpa, "#d62728", "MTPA (table)");
    const bool have_mtpv = curve(mtpv, "#1f77b4", "MTPV (table)");
    page.Figure(f, absl::StrFormat(
                       "Constant-torque contours from the fitted flux linkage (T = 1.5 p (psi_d iq - psi_q id)), the "
                       "current limit, the voltage limit |u| = %.3g V (m Udc / sqrt 3, Udc %.4g V) at %.0f rpm (%s), "
                       "and the MTPA and MTPV tables' points for motoring. Base speed at full MTPA torque: %.0f rpm.%s",
                       lim.UMaxV(), lim.udc_v, ell_rpm, H(ell_source), base_rpm,
                       have_mtpv ? "" : " The MTPV table has no row with positive torque to draw."));
  }
  b += "</section>\n";

  // ------------------------------------------------------------ fw maps
  b += "<section><h2>Field-weakening map</h2><div class=\"grid\">\n";
  {
    const auto& tq = fw.axes[0].values;
    const auto& n = fw.axes[1].values;
    for (size_t o = 0; o < fw.outputs.size(); ++o) {
      const auto& out = fw.outputs[o];
      plot::Figure f("fig-fw-" + out.name, 640, 420);
      f.SetTitle(absl::StrFormat("field weakening: %s", out.name == "id_a" ? "id" : "iq"));
      f.SetXLabel("speed [rpm]");
      f.SetYLabel("torque request [N m]");
      f.Heatmap(n, tq, out.values, out.name == "id_a" ? "id [A]" : "iq [A]");
      std::vector<double> cx, cy;
      for (size_t i = 0; i < tq.size(); ++i) {
        for (size_t j = 0; j < n.size(); ++j) {
          if (fw.clamped[i * n.size() + j]) {
            cx.push_back(n[j]);
            cy.push_back(tq[i]);
          }
        }
      }
      plot::Style st;
      st.colour = "#ffffff";
      st.marker_px = 1.6;
      // Legend-only grey twin: a white dot does not show on the page.
      f.Scatter(cx, cy, st, "");
      plot::Style key = st;
      key.colour = "#999";
      f.Scatter({}, {}, key, absl::StrFormat("clamped (%zu cells)", cx.size()));
      page.Figure(f, absl::StrFormat("The fw table's %s (%zu torque rows x %zu speeds, %g .. %g rpm) from the "
                                     "tables library; white dots mark cells where the request exceeded the limits.",
                                     out.name, tq.size(), n.size(), n.front(), n.back()));
    }
  }
  b += "</div></section>\n";

  // ------------------------------------------------------------ tables
  b += "<section><h2>ECU tables: limits and checksums</h2><table class=\"kv\">\n";
  b += Row("pole pairs / Rs", absl::StrFormat("%d / %.6g ohm", lim.pole_pairs, lim.rs_ohm));
  b += Row("current limit i_max", absl::StrFormat("%.4g A <small>(%s)</small>", lim.i_max_a, H(i_max_source)));
  b += Row("DC link Udc", absl::StrFormat("%.4g V <small>(%s)</small>", lim.udc_v, H(udc_source)));
  b += Row("voltage limit u_max", absl::StrFormat("%.4g V (modulation limit %.3g of the linear SVPWM range)", lim.UMaxV(),
                                                  lim.modulation_limit));
  b += Row("temperature", absl::StrFormat("%.3g degC", lim.temperature_c));
  b += "</table>\n<table class=\"list\"><tr><th>table</th><th>axes</th><th>outputs</th><th>cells</th>"
       "<th>clamped</th><th>extrapolated</th><th>by symmetry</th><th>not positive definite</th><th>CRC-32</th>"
       "<th>SHA-256</th></tr>\n";
  for (const char* kind : {"mtpa", "mtpv", "fw"}) {
    const auto& t = tabs[kind];
    std::vector<std::string> axes, outs;
    for (const auto& a : t.axes) {
      axes.push_back(absl::StrFormat("%s: %zu, %.4g .. %.4g", a.name, a.values.size(), a.values.front(), a.values.back()));
    }
    for (const auto& o : t.outputs) {
      const auto [lo, hi] = std::minmax_element(o.values.begin(), o.values.end());
      outs.push_back(absl::StrFormat("%s: %.4g .. %.4g", o.name, *lo, *hi));
    }
    size_t clamped = 0, extrapolated = 0, by_symmetry = 0, not_pd = 0;
    for (auto c : t.clamped) clamped += c;
    for (auto c : t.extrapolated) extrapolated += c;
    for (auto c : t.by_symmetry) by_symmetry += c;
    for (auto c : t.not_positive_definite) not_pd += c;
    b += absl::StrFormat("<tr><td>%s</td><td>%s</td><td>%s</td><td>%zu</td><td>%zu</td><td>%zu</td><td>%zu</td>"
                         "<td>%s</td><td><code>%08x</code></td><td><code class=\"sha\">%s</code></td></tr>\n",
                         kind, absl::StrJoin(axes, "<br>", [](std::string* o, const std::string& a) { o->append(H(a)); }),
                         H(absl::StrJoin(outs, "; ")), t.clamped.size(), clamped, extrapolated, by_symmetry,
                         not_pd > 0 ? absl::StrFormat("<b>%zu</b>", not_pd) : std::string("0"), t.crc32, t.sha256);
  }
  b += absl::StrCat("</table><p class=\"note\">Checksums over the canonical payload (docs/tables.md); <code>fluxcal "
                    "export cal.json --table KIND</code> with the same limits prints the same values as "
                    "<code>payload_crc32</code> / <code>payload_sha256</code>. Cells flagged <i>by symmetry</i> lie "
                    "on the iq half the data did not measure, where the calibration states the measured half "
                    "mirrored (", H(cal.IqRegionText()), "); <i>extrapolated</i> ones rest on no measured data; "
                    "<i>not positive definite</i> ones are no valid operating point of the model (its differential "
                    "inductance is not positive definite there).", mtpv_note.empty() ? "" : " ", H(mtpv_note),
                    "</p></section>\n");

  // ------------------------------------------------------------ fleet
  if (!in.fleet.empty()) {
    // z = (this motor - fleet mean) / fleet std at each point: where this
    // serial sits in the distribution of the latest calibrations.
    auto z = [](double v, double mean, double sd) {
      return sd > 0 ? absl::StrFormat("%+.2f", (v - mean) / sd) : std::string("&ndash;");
    };
    b += absl::StrCat("<section><h2>Fleet</h2><p class=\"note\">", H(in.fleet_source),
                      ". z: this motor's value minus the fleet mean, in fleet standard deviations.</p>"
                      "<table class=\"list\"><tr><th>id, iq</th><th>serials</th><th>Ldd: this / fleet (z)</th>"
                      "<th>Lqq: this / fleet (z)</th><th>psi_d: this / fleet (z)</th>"
                      "<th>torque: this / fleet (z)</th><th>flagged outliers</th></tr>\n");
    for (const auto& f : in.fleet) {
      const auto p = cal.Predict(f.id_a, f.iq_a);
      bool self = false;
      for (const auto& o : f.outliers) self |= o == cal.serial();
      b += absl::StrFormat(
          "<tr><td>%.4g A, %.4g A</td><td>%d</td><td>%.4g / %.4g &plusmn; %.2g uH (%s)</td>"
          "<td>%.4g / %.4g &plusmn; %.2g uH (%s)</td><td>%.5g / %.5g &plusmn; %.2g mWb (%s)</td>"
          "<td>%.4g / %.4g &plusmn; %.2g N m (%s)</td><td>%s</td></tr>\n",
          f.id_a, f.iq_a, f.serials, 1e6 * p.ldd_h, 1e6 * f.ldd_h_mean, 1e6 * f.ldd_h_std,
          z(p.ldd_h, f.ldd_h_mean, f.ldd_h_std), 1e6 * p.lqq_h, 1e6 * f.lqq_h_mean, 1e6 * f.lqq_h_std,
          z(p.lqq_h, f.lqq_h_mean, f.lqq_h_std), 1e3 * p.psi_d_wb, 1e3 * f.psi_d_wb_mean, 1e3 * f.psi_d_wb_std,
          z(p.psi_d_wb, f.psi_d_wb_mean, f.psi_d_wb_std), p.torque_nm, f.torque_nm_mean, f.torque_nm_std,
          z(p.torque_nm, f.torque_nm_mean, f.torque_nm_std),
          f.outliers.empty() ? std::string("none")
                             : H(absl::StrJoin(f.outliers, ", ")) + (self ? " <b>(this motor)</b>" : ""));
    }
    b += "</table></section>\n";
  }

  // ------------------------------------------------------------ diagnosis
  if (in.diagnosis) {
    const auto& d = *in.diagnosis;
    b += "<section><h2>Diagnosis</h2><table class=\"kv\">\n";
    b += Row("report", H(in.diagnosis_path));
    b += Row("serial", H(JsonText(d, "serial")));
    b += Row("verdict", "<b>" + H(JsonText(d, "verdict")) + "</b>");
    for (const char* m : {"baseline", "final"}) {
      if (d.contains(m) && d[m].is_object()) {
        b += Row(m, absl::StrFormat("model %s, residual RMS %s (relative), BIC %s", H(JsonText(d[m], "model")),
                                    H(JsonText(d[m], "residual_rms")), H(JsonText(d[m], "bic"))));
      }
    }
    b += "</table>\n";
    const auto mism = d.value("mismatches", nlohmann::json::array());
    // The findings marked into a diagnosed calibration come without the
    // mismatches: no count where none is known.
    if (d.contains("mismatches")) b += absl::StrFormat("<h3>Mismatches against the baseline (%zu)</h3>\n", mism.size());
    if (!mism.empty()) {
      b += "<table class=\"list\"><tr><th>signal</th><th>where</th><th>points</th><th>significance</th></tr>\n";
      for (const auto& m : mism) {
        std::vector<std::string> pts;
        for (const auto& p : m.value("points", nlohmann::json::array())) pts.push_back(ValueText(p));
        b += "<tr><td>" + H(JsonText(m, "signal")) + "</td><td>" + H(JsonText(m, "where")) + "</td><td>" +
             H(absl::StrJoin(pts, " ")) + "</td><td>" + H(JsonText(m, "significance_sigma")) + " sigma</td></tr>\n";
      }
      b += "</table>\n";
    }
    const auto finds = d.value("findings", nlohmann::json::array());
    b += absl::StrFormat("<h3>Findings (%zu, in the order accepted)</h3>\n", finds.size());
    if (!finds.empty()) {
      b += "<table class=\"list\"><tr><th>effect</th><th>explanation</th><th>parameters (+- std)</th>"
           "<th>residual RMS before / after</th><th>delta BIC</th></tr>\n";
      for (const auto& fd : finds) {
        std::vector<std::string> ps;
        const auto pars = fd.value("parameters", nlohmann::json::object());
        const auto stds = fd.value("parameter_std", nlohmann::json::object());
        for (auto it = pars.begin(); it != pars.end(); ++it) {
          std::string p = it.key() + " = " + ValueText(it.value());
          if (stds.contains(it.key())) p += " +- " + ValueText(stds[it.key()]);
          ps.push_back(p);
        }
        b += "<tr><td>" + H(JsonText(fd, "effect")) + "</td><td>" + H(JsonText(fd, "explanation")) + "</td><td>" +
             H(absl::StrJoin(ps, "; ")) + "</td><td>" + H(JsonText(fd, "residual_rms_before")) + " / " +
             H(JsonText(fd, "residual_rms_after")) + "</td><td>" + H(JsonText(fd, "delta_bic")) + "</td></tr>\n";
      }
      b += "</table>\n";
    }
    b += "</section>\n";
  }

  static const char* kCss = R"css(
body{font-family:sans-serif;margin:24px;color:#222;max-width:1360px}
h1{font-size:22px;margin:0 0 8px} h1 .ver{font-weight:normal;color:#666;font-size:16px}
h2{font-size:17px;border-bottom:1px solid #ccc;padding-bottom:4px;margin-top:28px} h3{font-size:14px}
.verdict{display:inline-block;padding:4px 12px;border-radius:4px;font-weight:bold;color:#fff}
.verdict.pass{background:#2a7d2a} .verdict.fail{background:#b02a2a}
table{border-collapse:collapse;font-size:13px} th,td{text-align:left;padding:3px 8px;vertical-align:top}
table.kv th{color:#555;font-weight:normal;white-space:nowrap}
table.list{margin:6px 0} table.list th{background:#f0f0f0} table.list td,table.list th{border:1px solid #ddd}
code.sha{font-size:11px;word-break:break-all}
pre.cands{background:#f7f7f7;padding:8px;font-size:12px;overflow-x:auto}
.grid{display:grid;grid-template-columns:repeat(2,max-content);gap:12px}
ul.excluded{font-size:13px}
figure{margin:8px 0;border:1px solid #e0e0e0;padding:6px;background:#fff}
figure svg{display:block}
figcaption{font-size:12px;color:#555;max-width:640px;margin-top:4px}
small,.note{color:#666;font-size:12px}
.warn{background:#fff3cd;border:1px solid #e0c060;padding:8px 12px;font-size:13px;max-width:1000px}
)css";
  rep.figures = page.figures;
  rep.html = "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>fluxcal report " + H(cal.serial()) +
             absl::StrFormat(" v%d", cal.version) + "</title>\n<style>" + kCss + "</style></head>\n<body>\n" + page.body +
             "</body></html>\n";
  return rep;
}

}  // namespace fluxcal::report
