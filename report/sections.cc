// The page's sections of words and numbers: identity and provenance, fit
// quality (with the model candidates), the ECU tables' limits and
// checksums, the fleet comparison, the diagnosis' findings.
#include <algorithm>
#include <map>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "report/format.h"
#include "report/internal.h"

namespace fluxcal::report::internal {
namespace {

// ------------------------------------------------------------ model table

// The fit's model-selection lines ("smooth cv=10.58 bic=651.64 chi2=236.63
// k=84.5 (selected)", "poly4 cv=... k=8.0 (rejected: why)") as table rows:
// the numbers rounded, the parenthesis as a note; a line of another shape
// as text.
std::string CandidatesTable(const std::vector<std::string>& lines) {
  std::string rows;
  for (const auto& line : lines) {
    const size_t paren = line.find(" (");
    const std::string head = line.substr(0, paren);
    std::string note = paren == std::string::npos ? "" : line.substr(paren + 2);
    if (!note.empty() && note.back() == ')') note.pop_back();
    std::vector<std::string> tok = absl::StrSplit(head, ' ', absl::SkipEmpty());
    if (tok.empty()) continue;
    std::map<std::string, double> kv;
    bool parsed = true;
    for (size_t k = 1; k < tok.size(); ++k) {
      const size_t eq = tok[k].find('=');
      double v = 0;
      if (eq == std::string::npos || !absl::SimpleAtod(tok[k].substr(eq + 1), &v)) {
        parsed = false;
        break;
      }
      kv[tok[k].substr(0, eq)] = v;
    }
    auto cell = [&](const char* key, Rounding r) { return kv.count(key) ? Num(kv[key], r) : std::string("&ndash;"); };
    if (!parsed) {
      rows += "<tr><td colspan=\"6\">" + H(RoundNumbersInText(line)) + "</td></tr>\n";
      continue;
    }
    rows += absl::StrFormat("<tr%s><td>%s</td><td>%s</td><td>%s</td><td>%s</td><td>%s</td><td>%s</td></tr>\n",
                            note == "selected" ? " class=\"selected\"" : "", H(tok[0]), cell("cv", Rounding{4, 0}),
                            cell("bic", kStatistic), cell("chi2", kStatistic), cell("k", Rounding{4, 0.1}),
                            H(RoundNumbersInText(note)));
  }
  return "<table class=\"list\"><tr><th>model</th><th>cross-validated error</th><th>BIC</th><th>chi2</th>"
         "<th>parameters (effective)</th><th></th></tr>\n" +
         rows + "</table>\n";
}

}  // namespace

// The header (serial, version, verdict, warnings) and where the calibration
// comes from.
void IdentitySection(const PageContext& ctx, Page* page) {
  const ReportInputs& in = *ctx.in;
  const fit::Calibration& cal = *ctx.cal;
  const PdScan& pd = ctx.pd;
  const std::string& limits_warning = ctx.limits_warning;
  const std::string& no_voltage = ctx.no_voltage;
  std::string& b = page->body;
  const nlohmann::json& cj = in.calibration_json;
  const std::string verdict = !in.verdict.empty() ? in.verdict : JsonText(cj, "verdict");
  const bool pass = verdict == "pass";
  b += absl::StrFormat("<header><h1>Calibration report: %s <span class=\"ver\">version %d</span></h1>\n", H(cal.serial()),
                       cal.version);
  b += absl::StrFormat("<div class=\"verdict %s\">%s</div></header>\n", pass ? "pass" : "fail",
                       verdict.empty() ? "no verdict" : H(verdict));
  if (!limits_warning.empty()) b += "<p class=\"warn\">" + H(limits_warning) + "</p>\n";
  if (!no_voltage.empty()) b += "<p class=\"warn\">" + H(no_voltage) + "</p>\n";
  if (pd.bad_by_source[0] > 0) {
    b += absl::StrFormat("<p class=\"warn\">The fitted inductance is not positive definite at %d grid nodes inside "
                         "the measured region (Fit quality, below): the surface is not a physical magnetic model "
                         "there. The verdict does not check this.</p>\n", pd.bad_by_source[0]);
  }
  b += "<section><h2>Identity and provenance</h2><table class=\"kv\">\n";
  b += Row("serial", H(cal.serial()));
  b += Row("calibration version", absl::StrCat(cal.version, cal.version == 0 ? " (not stored yet: versions are assigned by the store)" : ""));
  b += Row("model family", H(cal.family().Name()));
  b += Row("calibration from", H(in.calibration_path));
  const std::string created = JsonText(cj, "created_utc");
  b += Row("calibration created", created.empty() ? "not recorded in the file; file modified " + H(in.calibration_file_mtime_utc)
                                                  : H(created));
  const std::string sw = cj.is_object() && cj.contains("software_version") && cj["software_version"].is_string()
                             ? cj["software_version"].get<std::string>()
                             : "";
  b += Row("software that fitted it", sw.empty() ? "not recorded in the file" : H(sw));
  const std::string released = JsonText(cj, "released");
  b += Row("release state", released.empty() ? "not known from a file (the service knows: fluxcal report SERIAL --server ADDR)"
                                             : H(released));
  b += Row("recording set", in.set_path.empty() ? "not given (no identified points drawn)" : H(in.set_path));
  if (!in.map_path.empty()) b += Row("flux map", H(in.map_path) + " <small>(its nodes drawn over the surfaces)</small>");
  b += Row("verdict", (verdict.empty() ? "none" : H(verdict)) + (in.verdict_basis.empty() ? "" : " <small>(" + H(in.verdict_basis) + ")</small>"));
  b += Row("report written", H(NowUtc()) + " by fluxcal " + H(in.software_version));
  b += "</table></section>\n";
}

// The fit's numbers, the measured region, the model candidates and the
// excluded observations.
void FitSection(const PageContext& ctx, Page* page) {
  const fit::Calibration& cal = *ctx.cal;
  const Coverage& cov = ctx.cov;
  const PdScan& pd = ctx.pd;
  std::string& b = page->body;
  const auto& s = cal.summary;
  b += "<section><h2>Fit quality</h2><table class=\"kv\">\n";
  b += Row("usable", s.usable ? "yes" : "<b>no</b>");
  b += Row("termination", H(RoundNumbersInText(s.termination)));
  b += Row("observations", absl::StrCat(s.observations));
  // A map fit has no identified inductances for rms_relative to cover: its
  // figure is the flux error over the map's nodes (FitSummary::flux_*).
  if (s.flux_nodes == 0 || s.rms_relative > 0) {
    b += Row("RMS relative residual", Num(100 * s.rms_relative, kPercent, "%"));
  }
  if (s.flux_nodes > 0) {
    b += Row("flux error against the map",
             absl::StrFormat("RMS %s, max %s of the largest |psi| %s over %d nodes (RMS %s, max %s)",
                             Num(100 * s.flux_rms_relative, kPercent, "%"), Num(100 * s.flux_max_relative, kPercent, "%"),
                             Num(s.flux_scale_wb, kFluxWb, "Wb"), s.flux_nodes, Num(1e3 * s.flux_rms_wb, kFluxMwb, "mWb"),
                             Num(1e3 * s.flux_max_wb, kFluxMwb, "mWb")));
  }
  b += Row("chi2 / BIC", Num(s.chi2, kStatistic) + " / " + Num(s.bic, kStatistic));
  b += Row("psi_pm", Num(cal.psi_pm_wb(), kFluxWb, "Wb"));
  b += Row("psi_pm nominal", cal.psi_pm_nominal_wb() ? Num(*cal.psi_pm_nominal_wb(), kFluxWb, "Wb")
                                                     : std::string("not known (the data stated none)"));
  b += Row("Rs (nominal) / pole pairs",
           absl::StrFormat("%s / %d", cal.rs_ohm() ? Num(*cal.rs_ohm(), kResistanceOhm, "ohm") : "not known",
                           cal.pole_pairs()));
  // The magnet temperature dependence it states (fit::Calibration), or
  // what it lacks for tables at another magnet temperature.
  b += Row("magnet temperature", H(cal.MagnetTemperatureText()));
  b += Row("DC link Udc (of its data)",
           cal.udc_v() ? Num(*cal.udc_v(), kVoltageV, "V") : std::string("not known (the data stated none)"));
  b += Row("measured region", absl::StrFormat("id %s, iq %s <small>(from %s)</small>",
                                              Range(cov.id_lo, cov.id_hi, kCurrentA, "A"),
                                              Range(cov.iq_lo, cov.iq_hi, kCurrentA, "A"), H(cov.basis)));
  b += Row("the other half of the current plane", H(cov.OtherHalf()));
  // What the calibration itself says of the half of the iq axis nothing
  // measured: "by symmetry" when the model mirrors the measured one,
  // "extrapolated" otherwise (fit::Region).
  b += Row("iq halves (calibration)", H(cal.IqRegionText()));
  b += Row("positive definite inductance", H(PdText(pd)));
  b += "</table>\n";
  b += absl::StrFormat("<h3>Model candidates (%zu)</h3>\n", s.candidates.size());
  if (s.candidates.empty()) {
    b += "<p>none recorded (a single model was fitted)</p>\n";
  } else {
    b += CandidatesTable(s.candidates);
  }
  b += absl::StrFormat("<h3>Excluded or down-weighted observations (%zu)</h3>\n", s.excluded.size());
  if (s.excluded.empty()) {
    b += "<p>none</p>\n";
  } else {
    b += "<ul class=\"excluded\">";
    for (const auto& e : s.excluded) b += "<li>" + H(RoundNumbersInText(e)) + "</li>";
    b += "</ul>\n";
  }
  b += "</section>\n";
}

// The limits the tables were computed for, and per table its axes,
// outputs, flagged cells and checksums.
void TablesSection(const PageContext& ctx, Page* page) {
  const fit::Calibration& cal = *ctx.cal;
  const tables::MachineLimits& lim = ctx.lim;
  const auto& tabs = ctx.tabs;
  const std::string& mtpv_note = ctx.mtpv_note;
  const std::string& i_max_source = ctx.i_max_source;
  const std::string& udc_source = ctx.udc_source;
  std::string& b = page->body;
  b += "<section><h2>ECU tables: limits and checksums</h2><table class=\"kv\">\n";
  b += Row("pole pairs / Rs", absl::StrFormat("%d / %s", lim.pole_pairs,
                                              lim.rs_ohm ? Num(*lim.rs_ohm, kResistanceOhm, "ohm") : "not known"));
  b += Row("current limit i_max", absl::StrFormat("%s <small>(%s)</small>", Num(lim.i_max_a, kCurrentA, "A"),
                                                  H(i_max_source)));
  b += Row("DC link Udc", lim.udc_v ? absl::StrFormat("%s <small>(%s)</small>", Num(*lim.udc_v, kVoltageV, "V"),
                                                      H(udc_source))
                                    : std::string("not known <small>(no --udc-v, no set's drive.udc_v, none in the "
                                                  "calibration)</small>"));
  if (lim.udc_v) {
    b += Row("voltage limit u_max", absl::StrFormat("%s (modulation limit %s of the linear SVPWM range)",
                                                    Num(lim.UMaxV(), kVoltageV, "V"), Num(lim.modulation_limit, kRatio)));
  }
  b += Row("temperature", Num(lim.temperature_c, kTemperatureC, "degC"));
  b += "</table>\n<table class=\"list\"><tr><th>table</th><th>axes</th><th>outputs</th><th>cells</th>"
       "<th>clamped</th><th>extrapolated</th><th>by symmetry</th><th>not positive definite</th><th>CRC-32</th>"
       "<th>SHA-256</th></tr>\n";
  for (const char* kind : {"mtpa", "mtpv", "fw"}) {
    if (!tabs.count(kind)) {
      b += absl::StrFormat("<tr><td>%s</td><td colspan=\"9\">not computed: the voltage limit is not known (Udc or "
                           "Rs, above)</td></tr>\n", kind);
      continue;
    }
    const auto& t = tabs.at(kind);
    std::vector<std::string> axes, outs;
    for (const auto& a : t.axes) {
      axes.push_back(absl::StrFormat("%s: %zu, %s", a.name, a.values.size(),
                                     Range(a.values.front(), a.values.back(), RoundingOf(a.name), UnitOf(a.name))));
    }
    for (const auto& o : t.outputs) {
      const auto [lo, hi] = std::minmax_element(o.values.begin(), o.values.end());
      outs.push_back(absl::StrFormat("%s: %s", o.name, Range(*lo, *hi, RoundingOf(o.name), UnitOf(o.name))));
    }
    size_t clamped = 0, extrapolated = 0, by_symmetry = 0, not_pd = 0;
    for (auto c : t.clamped) clamped += c;
    for (auto c : t.extrapolated) extrapolated += c;
    for (auto c : t.by_symmetry) by_symmetry += c;
    for (auto c : t.not_positive_definite) not_pd += c;
    b += absl::StrFormat("<tr><td>%s</td><td>%s</td><td>%s</td><td>%zu</td><td>%zu</td><td>%zu</td><td>%zu</td>"
                         "<td>%s</td><td><code>%08x</code></td><td><code class=\"sha\">%s</code></td></tr>\n",
                         kind, absl::StrJoin(axes, "<br>", [](std::string* o, const std::string& a) { o->append(H(a)); }),
                         absl::StrJoin(outs, "<br>", [](std::string* o, const std::string& a) { o->append(H(a)); }),
                         t.clamped.size(), clamped, extrapolated, by_symmetry,
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
}

// With a fleet: this motor against the fleet's mean and spread.
void FleetSection(const PageContext& ctx, Page* page) {
  const ReportInputs& in = *ctx.in;
  const fit::Calibration& cal = *ctx.cal;
  std::string& b = page->body;
  if (!in.fleet.empty()) {
    // z = (this motor - fleet mean) / fleet std at each point: where this
    // serial sits in the distribution of the latest calibrations.
    auto z = [](double v, double mean, double sd) {
      if (!(sd > 0)) return std::string("&ndash;");
      const double zz = (v - mean) / sd;
      return (zz > 0 ? "+" : "") + Num(zz, kZ);
    };
    auto with = [](double mean, double sd, double scale, Rounding r, const char* unit) {
      return absl::StrFormat("%s &plusmn; %s", Num(scale * mean, r), Num(scale * sd, Rounding{2, r.resolution}, unit));
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
          "<tr><td>%s, %s</td><td>%d</td><td>%s / %s (%s)</td><td>%s / %s (%s)</td><td>%s / %s (%s)</td>"
          "<td>%s / %s (%s)</td><td>%s</td></tr>\n",
          Num(f.id_a, kCurrentA, "A"), Num(f.iq_a, kCurrentA, "A"), f.serials, Num(1e6 * p.ldd_h, kInductanceUh),
          with(f.ldd_h_mean, f.ldd_h_std, 1e6, kInductanceUh, "uH"), z(p.ldd_h, f.ldd_h_mean, f.ldd_h_std),
          Num(1e6 * p.lqq_h, kInductanceUh), with(f.lqq_h_mean, f.lqq_h_std, 1e6, kInductanceUh, "uH"),
          z(p.lqq_h, f.lqq_h_mean, f.lqq_h_std), Num(1e3 * p.psi_d_wb, kFluxMwb),
          with(f.psi_d_wb_mean, f.psi_d_wb_std, 1e3, kFluxMwb, "mWb"), z(p.psi_d_wb, f.psi_d_wb_mean, f.psi_d_wb_std),
          Num(p.torque_nm, kTorqueNm), with(f.torque_nm_mean, f.torque_nm_std, 1, kTorqueNm, "N m"),
          z(p.torque_nm, f.torque_nm_mean, f.torque_nm_std),
          f.outliers.empty() ? std::string("none")
                             : H(absl::StrJoin(f.outliers, ", ")) + (self ? " <b>(this motor)</b>" : ""));
    }
    b += "</table></section>\n";
  }
}

// With a diagnosis: its verdict, mismatches, findings and figures.
void DiagnosisSection(const PageContext& ctx, Page* page) {
  const ReportInputs& in = *ctx.in;
  std::string& b = page->body;
  if (in.diagnosis) {
    const auto& d = *in.diagnosis;
    b += "<section><h2>Diagnosis</h2><table class=\"kv\">\n";
    b += Row("report", H(in.diagnosis_path));
    b += Row("serial", H(JsonText(d, "serial")));
    b += Row("verdict", "<b>" + H(JsonText(d, "verdict")) + "</b>");
    for (const char* m : {"baseline", "final"}) {
      if (d.contains(m) && d[m].is_object()) {
        b += Row(m, absl::StrFormat("model %s, residual RMS %s (relative), BIC %s", H(JsonText(d[m], "model")),
                                    H(PercentText(d[m], "residual_rms")), H(JsonText(d[m], "bic", kStatistic))));
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
             H(absl::StrJoin(pts, " ")) + "</td><td>" + H(JsonText(m, "significance_sigma", kSigma)) +
             " sigma</td></tr>\n";
      }
      b += "</table>\n";
    }
    const auto finds = d.value("findings", nlohmann::json::array());
    b += absl::StrFormat("<h3>Findings (%zu, in the order accepted)</h3>\n", finds.size());
    if (!finds.empty()) {
      b += "<table class=\"list\"><tr><th>effect</th><th>explanation</th><th>parameters (± std)</th>"
           "<th>residual RMS before / after</th><th>delta BIC</th></tr>\n";
      for (const auto& fd : finds) {
        std::vector<std::string> ps;
        const auto pars = fd.value("parameters", nlohmann::json::object());
        const auto stds = fd.value("parameter_std", nlohmann::json::object());
        for (auto it = pars.begin(); it != pars.end(); ++it) {
          if (!it.value().is_number()) {
            ps.push_back(it.key() + " = " + ValueText(it.value()));
            continue;
          }
          const double sd = stds.contains(it.key()) && stds[it.key()].is_number() ? stds[it.key()].get<double>() : 0.0;
          ps.push_back(it.key() + " = " + ValueWithStd(it.key(), it.value().get<double>(), sd));
        }
        b += "<tr><td>" + H(JsonText(fd, "effect")) + "</td><td>" + H(JsonText(fd, "explanation")) + "</td><td>" +
             H(absl::StrJoin(ps, "; ")) + "</td><td>" + H(PercentText(fd, "residual_rms_before")) + " / " +
             H(PercentText(fd, "residual_rms_after")) + "</td><td>" + H(JsonText(fd, "delta_bic", kStatistic)) +
             "</td></tr>\n";
      }
      b += "</table>\n";
    }
    if (!in.diagnosis_figures_note.empty()) b += "<p class=\"note\">" + H(in.diagnosis_figures_note) + "</p>\n";
    for (const auto& fig : in.diagnosis_figures) page->Svg(fig.svg, H(fig.caption));
    b += "</section>\n";
  }
}

}  // namespace fluxcal::report::internal
