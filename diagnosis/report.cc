#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <sstream>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/strings/numbers.h"
#include "diagnosis/diagnose.h"
#include "io/csv.h"
#include "nlohmann/json.hpp"

namespace fluxcal::diag {

nlohmann::json MarkedCalibrationJson(const DiagnosisReport& r, const fit::Calibration& cal) {
  nlohmann::json j = cal.ToJson();
  nlohmann::json marks = nlohmann::json::array();
  for (const auto& f : r.findings) marks.push_back({{"effect", f.effect}, {"parameters", f.parameters}});
  j["diagnosis"] = {{"format", "fluxcal.diagnosis.v1"}, {"verdict", r.verdict}, {"findings", marks}};
  return j;
}

nlohmann::json ToJson(const DiagnosisReport& r) {
  using nlohmann::json;
  json j;
  j["format"] = "fluxcal.diagnosis.v1";
  j["serial"] = r.serial;
  j["verdict"] = r.verdict;
  j["baseline"] = {{"model", r.baseline.model}, {"residual_rms", r.baseline.residual_rms}, {"bic", r.baseline.bic}};
  j["mismatches"] = json::array();
  for (const auto& m : r.mismatches) {
    j["mismatches"].push_back({{"signal", m.signal}, {"where", m.where}, {"points", m.points},
                               {"significance_sigma", m.significance_sigma}});
  }
  j["findings"] = json::array();
  for (const auto& f : r.findings) {
    json alternatives = json::array();
    for (const auto& a : f.alternatives) {
      alternatives.push_back({{"effect", a.effect},
                              {"parameters", a.parameters.empty() ? json::object() : json(a.parameters)},
                              {"why", a.why}});
    }
    j["findings"].push_back({{"effect", f.effect}, {"explanation", f.explanation},
                             {"parameters", f.parameters.empty() ? json::object() : json(f.parameters)},
                             {"parameter_std", f.parameter_std.empty() ? json::object() : json(f.parameter_std)},
                             {"residual_rms_before", f.residual_rms_before}, {"residual_rms_after", f.residual_rms_after},
                             {"delta_bic", f.delta_bic}, {"alternatives", alternatives}});
  }
  j["final"] = {{"model", r.final_model.model}, {"residual_rms", r.final_model.residual_rms}, {"bic", r.final_model.bic}};
  // Compatible extensions (docs/diagnosis.md): what is still significant
  // after the refit, and the corrected differential inductances.
  j["remaining_mismatches"] = json::array();
  for (const auto& m : r.remaining) {
    j["remaining_mismatches"].push_back({{"signal", m.signal}, {"where", m.where}, {"points", m.points},
                                         {"significance_sigma", m.significance_sigma}});
  }
  j["held_out"] = json::array();
  for (const auto& h : r.held_out) {
    j["held_out"].push_back({{"signal", h.signal}, {"significance_sigma", h.significance_sigma},
                             {"residual_rms", h.residual_rms}, {"passed", h.passed}});
  }
  j["rejected_candidates"] = json::array();
  for (const auto& c : r.rejected) {
    j["rejected_candidates"].push_back(
        {{"effect", c.effect}, {"reason", c.reason}, {"delta_bic", c.delta_bic}, {"significance", c.significance}});
  }
  j["corrected_inductances"] = json::array();
  for (const auto& c : r.corrected) {
    j["corrected_inductances"].push_back({{"point", c.point}, {"id_a", c.id_a}, {"iq_a", c.iq_a}, {"ldd_h", c.ldd_h},
                                          {"lqq_h", c.lqq_h}, {"ldq_h", c.ldq_h}, {"ldd_h_identified", c.ldd_h_identified},
                                          {"lqq_h_identified", c.lqq_h_identified}});
  }
  j["waveform"] = {{"replay", "open-loop: recorded commands and angles through the twin"},
                   {"residual_rms_before_a", r.waveform_rms_before_a},
                   {"residual_rms_after_a", r.waveform_rms_after_a},
                   {"spectrum_hz", r.spectrum_hz},
                   {"spectrum_before_a", r.spectrum_before_a},
                   {"spectrum_after_a", r.spectrum_after_a},
                   {"significant_hz_before", r.significant_hz_before},
                   {"significant_hz_after", r.significant_hz_after}};
  j["seconds"] = r.seconds;
  return j;
}

std::string ToText(const DiagnosisReport& r) {
  std::string s = absl::StrFormat("Diagnosis of %s: %s.\n", r.serial, r.verdict);
  s += absl::StrFormat("The nominal model (manifest Rs and psi_pm, self-axis saturation only, dead time compensated, "
                       "ideal sensors) leaves a relative residual of %.3g %%.\n", 100 * r.baseline.residual_rms);
  if (r.mismatches.empty()) {
    s += "No region of the operating space or signal departs from it beyond the noise estimated from the data.\n";
  }
  for (const auto& m : r.mismatches) {
    s += absl::StrFormat("  Mismatch in %s at %s: %.1f sigma%s%s.\n", m.signal, m.where, m.significance_sigma,
                         m.points.empty() ? "" : ", worst points ", absl::StrJoin(m.points, ", "));
  }
  for (size_t k = 0; k < r.findings.size(); ++k) {
    const auto& f = r.findings[k];
    std::vector<std::string> ps;
    for (const auto& [name, v] : f.parameters) {
      const auto it = f.parameter_std.find(name);
      ps.push_back(it == f.parameter_std.end() ? absl::StrFormat("%s = %.4g", name, v)
                                               : absl::StrFormat("%s = %.4g +- %.2g", name, v, it->second));
    }
    s += absl::StrFormat("%zu. %s: %s. %s Residual %.3g %% -> %.3g %% (delta BIC %.1f).\n", k + 1, f.effect,
                         f.explanation, ps.empty() ? "" : absl::StrCat("Fitted ", absl::StrJoin(ps, ", "), "."),
                         100 * f.residual_rms_before, 100 * f.residual_rms_after, f.delta_bic);
    for (const auto& a : f.alternatives) {
      std::vector<std::string> as;
      for (const auto& [name, v] : a.parameters) as.push_back(absl::StrFormat("%s = %.4g", name, v));
      s += absl::StrFormat("   Equally: %s (%s): %s.\n", a.effect, absl::StrJoin(as, ", "), a.why);
    }
  }
  if (!r.findings.empty()) {
    s += absl::StrFormat("With %s the residual is %.3g %% (%.1fx lower).\n", r.final_model.model,
                         100 * r.final_model.residual_rms,
                         r.final_model.residual_rms > 0 ? r.baseline.residual_rms / r.final_model.residual_rms : 0.0);
  }
  for (const auto& m : r.remaining) {
    s += absl::StrFormat("  Still unexplained: %s at %s (%.1f sigma).\n", m.signal, m.where, m.significance_sigma);
  }
  for (const auto& h : r.held_out) {
    s += absl::StrFormat("  Fitted without %s, the final model predicts it to %.1f sigma (relative RMS %.3g %%)%s.\n",
                         h.signal, h.significance_sigma, 100 * h.residual_rms,
                         h.passed ? "" : ": not predicted, the findings do not account for it");
  }
  for (const auto& c : r.rejected) {
    if (r.verdict == "explained" || r.verdict == "no_mismatch") break;
    s += absl::StrFormat("  Rejected %s: %s.\n", c.effect, c.reason);
  }
  if (!r.spectrum_hz.empty()) {
    s += absl::StrFormat("Replaying every test through the twin with the recorded commands: phase-current residual "
                         "%.3g A RMS with the nominal model, %.3g A with the final one.\n",
                         r.waveform_rms_before_a, r.waveform_rms_after_a);
    auto hz = [](const std::vector<double>& v) {
      std::vector<std::string> o;
      for (double f : v) o.push_back(absl::StrFormat("%.0f", f));
      return o.empty() ? std::string("nowhere") : absl::StrCat("at ", absl::StrJoin(o, ", "), " Hz");
    };
    s += absl::StrFormat("The replay residual stands out (20 dB above its median bin) %s before, %s after.\n",
                         hz(r.significant_hz_before), hz(r.significant_hz_after));
  }
  s += absl::StrFormat("(%.2f s)\n", r.seconds);
  return s;
}

std::string ResidualMapSvg(const DiagnosisReport& r, bool after) {
  // One panel per standstill signal (HF phasors, held DC voltages): a cell
  // per operating point on the (id, iq) grid, coloured by the normalised
  // residual |z| (its RMS per real component, in sigma) and labelled with
  // it. Green below 2 sigma, amber to 5, red above.
  const char* signals[2] = {"hf_current", "dc_voltage"};
  std::vector<double> ids, iqs;
  for (const auto& z : r.residuals) {
    if (z.speed_rpm != 0 || (z.signal != signals[0] && z.signal != signals[1])) continue;
    ids.push_back(z.id_a);
    iqs.push_back(z.iq_a);
  }
  auto levels = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    std::vector<double> out;
    for (double x : v) if (out.empty() || x - out.back() > 3.0) out.push_back(x);   // held to +-3 A
    return out;
  };
  const auto lx = levels(ids), ly = levels(iqs);
  auto nearest = [](const std::vector<double>& l, double v) {
    size_t best = 0;
    for (size_t k = 1; k < l.size(); ++k) if (std::abs(l[k] - v) < std::abs(l[best] - v)) best = k;
    return best;
  };
  const double pw = 360, ph = 320, y0 = 50;
  const double cw = lx.empty() ? pw : pw / lx.size(), ch = ly.empty() ? ph : ph / ly.size();
  std::string s = absl::StrFormat(
      "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"880\" height=\"440\" font-family=\"sans-serif\" "
      "font-size=\"11\">\n<text x=\"60\" y=\"18\" font-size=\"13\">%s: normalised residual per standstill point, "
      "%s the findings (|z| in sigma; green &lt; 2, amber &lt; 5, red &gt;= 5)</text>\n",
      r.serial, after ? "after" : "before");
  for (int p = 0; p < 2; ++p) {
    const double x0 = 60 + p * 430;
    s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" font-size=\"12\">%s</text>\n", x0, y0 - 8, signals[p]);
    s += absl::StrFormat("<rect x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"#eee\" stroke=\"black\"/>\n",
                         x0, y0, pw, ph);
    for (size_t i = 0; i < lx.size(); ++i) {
      s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%.0f</text>\n", x0 + (i + 0.5) * cw,
                           y0 + ph + 14, std::round(lx[i]) + 0.0);
    }
    for (size_t j = 0; j < ly.size(); ++j) {
      s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"end\">%.0f</text>\n", x0 - 4,
                           y0 + ph - (j + 0.5) * ch + 4, std::round(ly[j]) + 0.0);
    }
    s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">id [A]</text>\n", x0 + pw / 2, y0 + ph + 30);
    s += absl::StrFormat("<text x=\"%.1f\" y=\"%.1f\" transform=\"rotate(-90 %.1f %.1f)\" text-anchor=\"middle\">iq [A]</text>\n",
                         x0 - 36, y0 + ph / 2, x0 - 36, y0 + ph / 2);
    for (const auto& z : r.residuals) {
      if (z.speed_rpm != 0 || z.signal != signals[p]) continue;
      const double v = after ? z.after : z.before;
      const size_t i = nearest(lx, z.id_a), j = nearest(ly, z.iq_a);
      const char* fill = v < 2 ? "#8c8" : (v < 5 ? "#fc6" : "#e55");
      const double cx = x0 + i * cw, cy = y0 + ph - (j + 1) * ch;
      s += absl::StrFormat(
          "<rect class=\"point\" x=\"%.1f\" y=\"%.1f\" width=\"%.1f\" height=\"%.1f\" fill=\"%s\" stroke=\"white\">"
          "<title>%s %s |z| = %.2f</title></rect>\n<text x=\"%.1f\" y=\"%.1f\" text-anchor=\"middle\">%.1f</text>\n",
          cx, cy, cw, ch, fill, z.point, z.signal, v, cx + cw / 2, cy + ch / 2 + 4, v);
    }
  }
  s += "</svg>\n";
  return s;
}

std::string SpectrumSvg(const DiagnosisReport& r) {
  const double x0 = 80, y0 = 30, w = 560, h = 380;
  double top = 1e-9;
  for (double v : r.spectrum_before_a) top = std::max(top, v);
  for (double v : r.spectrum_after_a) top = std::max(top, v);
  // Log axis over five decades below the next power of ten above the top.
  constexpr int kDecades = 5;
  const double hi = std::pow(10.0, std::ceil(std::log10(top))), lo = hi * std::pow(10.0, -kDecades);
  std::string s = "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"760\" height=\"460\" font-family=\"sans-serif\" font-size=\"11\">\n";
  s += absl::StrFormat("<text x=\"%g\" y=\"18\">%s: spectrum of the replay residual (complex alpha-beta); red = nominal "
                       "model, blue = final model</text>\n", x0, r.serial);
  s += absl::StrFormat("<rect x=\"%g\" y=\"%g\" width=\"%g\" height=\"%g\" fill=\"none\" stroke=\"black\"/>\n", x0, y0, w, h);
  auto y = [&](double v) { return y0 + h - h * std::log10(std::max(v, lo) / lo) / kDecades; };
  for (int d = 0; d <= kDecades; ++d) {
    const double v = lo * std::pow(10.0, d);
    s += absl::StrFormat("<line x1=\"%g\" y1=\"%.1f\" x2=\"%g\" y2=\"%.1f\" stroke=\"#ddd\"/>"
                         "<text x=\"%g\" y=\"%.1f\" text-anchor=\"end\">%.0e A</text>\n",
                         x0, y(v), x0 + w, y(v), x0 - 4, y(v) + 4, v);
  }
  const size_t n = r.spectrum_hz.size();
  for (size_t k = 0; k < n; ++k) {
    const double x = x0 + w * (k + 0.5) / n;
    s += absl::StrFormat("<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#c33\" stroke-width=\"2.5\"/>\n",
                         x - 1.3, y0 + h, x - 1.3, y(r.spectrum_before_a[k]));
    s += absl::StrFormat("<line x1=\"%.1f\" y1=\"%.1f\" x2=\"%.1f\" y2=\"%.1f\" stroke=\"#36c\" stroke-width=\"2.5\"/>\n",
                         x + 1.3, y0 + h, x + 1.3, y(r.spectrum_after_a[k]));
    if (static_cast<int>(r.spectrum_hz[k]) % 500 == 0) {
      s += absl::StrFormat("<text x=\"%.1f\" y=\"%g\" text-anchor=\"middle\">%.0f</text>\n", x, y0 + h + 14, r.spectrum_hz[k]);
    }
  }
  s += absl::StrFormat("<text x=\"%g\" y=\"450\" text-anchor=\"middle\">frequency [Hz]</text>\n</svg>\n", x0 + w / 2);
  return s;
}

absl::StatusOr<std::vector<Table1Row>> ReadTable1(const std::string& path) {
  auto text = io::ReadFileToString(path);
  if (!text.ok()) return text.status();
  std::vector<Table1Row> rows;
  int line_no = 0;
  bool header = false;
  for (absl::string_view line : absl::StrSplit(*text, '\n')) {
    ++line_no;
    if (line.empty() || line[0] == '#') continue;
    if (!header) {
      if (line != "iq_a,lq_hf_h,lq_ss_h") {
        return absl::InvalidArgumentError(absl::StrCat(path, ":", line_no, ": field 'header': expected iq_a,lq_hf_h,lq_ss_h"));
      }
      header = true;
      continue;
    }
    std::vector<std::string> f = absl::StrSplit(line, ',');
    Table1Row r;
    if (f.size() != 3 || !absl::SimpleAtod(f[0], &r.iq_a) || !absl::SimpleAtod(f[1], &r.lq_hf_h) ||
        !absl::SimpleAtod(f[2], &r.lq_ss_h)) {
      return absl::InvalidArgumentError(absl::StrCat(path, ":", line_no, ": field 'iq_a': expected three numbers"));
    }
    rows.push_back(r);
  }
  return rows;
}

Table1Result DiagnoseTable1(const std::vector<Table1Row>& rows) {
  Table1Result out;
  // Before: the HF (differential) Lq taken as the steady-state (apparent) one.
  // After: Lq_app(iq) = (1/iq) int_0^iq Lqq(i) di, the differential values
  // integrated by the trapezoidal rule on the table's own grid (at iq = 0 the
  // apparent equals the differential inductance).
  double s_before = 0, s_after = 0;
  double integral = 0;
  std::vector<double> resid;
  for (size_t k = 0; k < rows.size(); ++k) {
    if (k > 0) integral += 0.5 * (rows[k].lq_hf_h + rows[k - 1].lq_hf_h) * (rows[k].iq_a - rows[k - 1].iq_a);
    const double app = rows[k].iq_a > 0 ? integral / rows[k].iq_a : rows[k].lq_hf_h;
    out.lq_app_from_hf_h.push_back(app);
    const double b = rows[k].lq_hf_h / rows[k].lq_ss_h - 1, a = app / rows[k].lq_ss_h - 1;
    s_before += b * b;
    s_after += a * a;
    resid.push_back(b);
  }
  const double n = std::max<size_t>(1, rows.size());
  out.rms_before = std::sqrt(s_before / n);
  out.rms_after = std::sqrt(s_after / n);
  // Locate: does the mismatch grow with current? Least-squares slope of the
  // relative residual against iq with its standard error from the scatter.
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (size_t k = 0; k < rows.size(); ++k) {
    sx += rows[k].iq_a; sy += resid[k]; sxx += rows[k].iq_a * rows[k].iq_a; sxy += rows[k].iq_a * resid[k];
  }
  const double den = n * sxx - sx * sx;
  out.trend_slope_per_a = den > 0 ? (n * sxy - sx * sy) / den : 0.0;
  const double icpt = (sy - out.trend_slope_per_a * sx) / n;
  double ss = 0;
  for (size_t k = 0; k < rows.size(); ++k) {
    const double e = resid[k] - icpt - out.trend_slope_per_a * rows[k].iq_a;
    ss += e * e;
  }
  const double se = n > 2 && den > 0 ? std::sqrt(ss / (n - 2) * n / den) : 0.0;
  out.trend_sigma = se > 0 ? std::abs(out.trend_slope_per_a) / se : 0.0;
  if (out.rms_after < out.rms_before && out.trend_slope_per_a < 0) out.finding = "differential_inductance";
  for (size_t k = 0; k < rows.size(); ++k) {
    out.max_before = std::max(out.max_before, std::abs(rows[k].lq_hf_h / rows[k].lq_ss_h - 1));
    out.max_after = std::max(out.max_after, std::abs(out.lq_app_from_hf_h[k] / rows[k].lq_ss_h - 1));
  }
  // Alternatives for what is left: on the rows with iq > 0, the steady-state
  // value predicted from the integrated apparent Lq `a` as
  //  - noise only: a (no parameter);
  //  - a common scale k: k a -- an HF inductance biased by one factor (e.g.
  //    injection voltage lost to dead time or a sample-and-hold magnitude
  //    error), or a speed / voltage scale error in the steady-state test;
  //  - an HF bias b: a + b -- an additive error of every HF value (b
  //    integrates to itself);
  //  - a voltage offset c: a + c / iq -- a constant error in u_d at the
  //    test's speed (angle offset or delay: u_d picks up u_q x angle), which
  //    divided by w_e i_q grows at low current.
  // Each by least squares on the relative error; BIC = n ln(rss/n) + k ln n.
  std::vector<double> iq, a, lss;
  for (size_t k = 0; k < rows.size(); ++k) {
    if (rows[k].iq_a <= 0) continue;
    iq.push_back(rows[k].iq_a);
    a.push_back(out.lq_app_from_hf_h[k]);
    lss.push_back(rows[k].lq_ss_h);
  }
  const size_t m = iq.size();
  if (m >= 3) {
    // Relative residual r = pred/ss - 1 with pred = a + p g (g the
    // hypothesis' regressor) or k a: linear least squares in one parameter.
    auto fit1 = [&](const std::function<double(size_t)>& base, const std::function<double(size_t)>& g,
                    double* p) {
      double num = 0, den = 0;
      for (size_t k = 0; k < m; ++k) {
        const double y = 1 - base(k) / lss[k], x = g(k) / lss[k];
        num += x * y;
        den += x * x;
      }
      *p = den > 0 ? num / den : 0.0;
    };
    auto stats = [&](const std::function<double(size_t)>& pred, int params, Table1Result::Alternative* alt) {
      double rss = 0, mx = 0;
      for (size_t k = 0; k < m; ++k) {
        const double r = pred(k) / lss[k] - 1;
        rss += r * r;
        mx = std::max(mx, std::abs(r));
      }
      alt->rms = std::sqrt(rss / m);
      alt->max = mx;
      return m * std::log(std::max(rss, 1e-300) / m) + params * std::log(static_cast<double>(m));
    };
    Table1Result::Alternative noise{"estimation_noise", "the values' own estimation errors only", 0, "", 0, 0, 0};
    const double bic0 = stats([&](size_t k) { return a[k]; }, 0, &noise);
    out.alternatives.push_back(noise);
    Table1Result::Alternative gain{"common_scale", "one factor between HF and steady-state values (k x apparent)",
                                   0, "1", 0, 0, 0};
    // k minimises sum (k a/ss - 1)^2.
    double num = 0, den = 0;
    for (size_t k = 0; k < m; ++k) { num += a[k] / lss[k]; den += (a[k] / lss[k]) * (a[k] / lss[k]); }
    const double kk = den > 0 ? num / den : 1.0;
    gain.parameter = kk;
    gain.delta_bic = stats([&](size_t k) { return kk * a[k]; }, 1, &gain) - bic0;
    out.alternatives.push_back(gain);
    Table1Result::Alternative bias{"hf_bias", "an additive error of every HF value (apparent + b)", 0, "H", 0, 0, 0};
    double b;
    fit1([&](size_t k) { return a[k]; }, [](size_t) { return 1.0; }, &b);
    bias.parameter = b;
    bias.delta_bic = stats([&](size_t k) { return a[k] + b; }, 1, &bias) - bic0;
    out.alternatives.push_back(bias);
    Table1Result::Alternative off{"voltage_offset",
                                  "a constant u_d error at the test speed, e.g. an angle offset or delay "
                                  "(apparent + c / iq)",
                                  0, "H A", 0, 0, 0};
    double c;
    fit1([&](size_t k) { return a[k]; }, [&](size_t k) { return 1.0 / iq[k]; }, &c);
    off.parameter = c;
    off.delta_bic = stats([&](size_t k) { return a[k] + c / iq[k]; }, 1, &off) - bic0;
    out.alternatives.push_back(off);
  }
  return out;
}

}  // namespace fluxcal::diag
