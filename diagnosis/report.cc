#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <sstream>
#include <tuple>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "absl/strings/numbers.h"
#include "diagnosis/diagnose.h"
#include "io/csv.h"
#include "nlohmann/json.hpp"
#include "plot/plot.h"

namespace fluxcal::diag {

nlohmann::json MarkedCalibrationJson(const DiagnosisReport& r, const fit::Calibration& cal) {
  nlohmann::json j = cal.ToJson();
  nlohmann::json marks = nlohmann::json::array();
  for (const auto& f : r.findings) marks.push_back({{"effect", f.effect}, {"parameters", f.parameters}});
  j["diagnosis"] = {{"format", "fluxcal.diagnosis.v1"}, {"verdict", r.verdict}, {"findings", marks}};
  return j;
}

namespace {
// A located mismatch: the contract's four fields, then the compatible
// extensions (docs/diagnosis-report.md) where they say something.
nlohmann::json MismatchJson(const Mismatch& m) {
  using nlohmann::json;
  json j = {{"signal", m.signal}, {"where", m.where}, {"points", m.points},
            {"significance_sigma", m.significance_sigma}};
  if (!m.kind.empty()) j["kind"] = m.kind;
  if (m.order != 0) j["order"] = m.order;
  if (m.frequency_hz != 0) j["frequency_hz"] = m.frequency_hz;
  if (m.size_a > 0) j["size_a"] = m.size_a;
  if (!m.dependence.empty()) j["dependence"] = m.dependence;
  if (!m.hypotheses.empty()) {
    json hs = json::array();
    for (const auto& h : m.hypotheses) {
      json x = {{"physics", h.physics}, {"predicts", h.predicts}};
      if (!h.effect.empty()) x["effect"] = h.effect;
      hs.push_back(x);
    }
    j["hypotheses"] = hs;
  }
  return j;
}

std::string MismatchText(const Mismatch& m) {
  // A waveform line's place already reads "at speed, ...".
  const bool says_at = m.where.rfind("at ", 0) == 0;
  std::string s = absl::StrFormat("%s %s%s: %.1f sigma", m.signal, says_at ? "" : "at ", m.where, m.significance_sigma);
  // size_a is in the signal's unit (docs/diagnosis-report.md).
  const char* unit = m.signal == "rotor_angle" ? "rad" : m.signal == "phase_voltage" ? "V" : "A";
  if (m.size_a > 0) s += absl::StrFormat(", up to %.3g %s", m.size_a, unit);
  if (!m.points.empty()) s += absl::StrCat(", worst points ", absl::StrJoin(m.points, ", "));
  if (!m.dependence.empty()) s += absl::StrCat("; ", m.dependence);
  return s;
}

std::string HypothesesText(const Mismatch& m) {
  std::string s;
  for (size_t k = 0; k < m.hypotheses.size(); ++k) {
    const auto& h = m.hypotheses[k];
    s += absl::StrFormat("      %zu) %s%s; it would %s.\n", k + 1, h.physics,
                         h.effect.empty() ? " (not in the catalogue)" : absl::StrCat(" (", h.effect, ")"), h.predicts);
  }
  return s;
}
}  // namespace

nlohmann::json ToJson(const DiagnosisReport& r) {
  using nlohmann::json;
  json j;
  j["format"] = "fluxcal.diagnosis.v1";
  j["serial"] = r.serial;
  j["verdict"] = r.verdict;
  j["baseline"] = {{"model", r.baseline.model}, {"residual_rms", r.baseline.residual_rms}, {"bic", r.baseline.bic}};
  j["mismatches"] = json::array();
  for (const auto& m : r.mismatches) j["mismatches"].push_back(MismatchJson(m));
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
  for (const auto& m : r.remaining) j["remaining_mismatches"].push_back(MismatchJson(m));
  j["held_out"] = json::array();
  for (const auto& h : r.held_out) {
    j["held_out"].push_back({{"signal", h.signal}, {"significance_sigma", h.significance_sigma},
                             {"residual_rms", h.residual_rms}, {"passed", h.passed}});
    if (h.parameter_shift_sigma >= 0) {
      j["held_out"].back()["parameter_shift_sigma"] = h.parameter_shift_sigma;
      j["held_out"].back()["parameter_shift_material"] = h.parameter_shift_material;
    }
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
  s += absl::StrFormat("The nominal model (manifest Rs and psi_pm, the set's own calibration as its magnetics, dead "
                       "time as the manifest declares, ideal sensors) leaves a relative residual of %.3g %%.\n",
                       100 * r.baseline.residual_rms);
  if (r.mismatches.empty()) {
    s += "No region of the operating space or signal departs from it beyond the noise estimated from the data.\n";
  }
  for (const auto& m : r.mismatches) s += absl::StrCat("  Mismatch in ", MismatchText(m), ".\n");
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
    s += absl::StrCat("  Still unexplained: ", MismatchText(m), ".\n");
    if (!m.hypotheses.empty()) s += absl::StrCat("    What could make it, most likely first:\n", HypothesesText(m));
  }
  for (const auto& h : r.held_out) {
    s += absl::StrFormat("  Fitted without %s, the final model predicts it to %.1f sigma (relative RMS %.3g %%)%s.\n",
                         h.signal, h.significance_sigma, 100 * h.residual_rms,
                         h.passed ? "" : ": not predicted, the findings do not account for it");
    if (h.parameter_shift_sigma >= 0) {
      s += absl::StrFormat("    (the magnetics from the other classes miss it; every effect is found without it and moves "
                           "%.1f sigma%s: %s)\n",
                           h.parameter_shift_sigma,
                           h.parameter_shift_material ? "" : ", less than any parameter's materiality floor",
                           h.passed ? "consistent" : "not consistent");
    }
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
  // per operating point on the (id, iq) grid, coloured by the class of the
  // normalised residual |z| (its RMS per real component, in sigma) and
  // labelled with it: green below 2 sigma, amber to 5, red from 5.
  const char* signals[2] = {"hf_current", "dc_voltage"};
  const char* what[2] = {"HF current phasors", "held DC voltages"};
  std::vector<double> ids, iqs;
  for (const auto& z : r.residuals) {
    if (z.speed_rpm != 0 || (z.signal != signals[0] && z.signal != signals[1])) continue;
    ids.push_back(z.id_a);
    iqs.push_back(z.iq_a);
  }
  // Grid levels: operating points are held to their reference within
  // +-3 A; a level is the mean of the currents it gathers.
  auto levels = [](std::vector<double> v) {
    std::sort(v.begin(), v.end());
    std::vector<double> sum;
    std::vector<int> count;
    for (double x : v) {
      if (sum.empty() || x - sum.back() / count.back() > 3.0) {
        sum.push_back(x);
        count.push_back(1);
      } else {
        sum.back() += x;
        ++count.back();
      }
    }
    for (size_t k = 0; k < sum.size(); ++k) sum[k] /= count[k];
    return sum;
  };
  const auto lx = levels(ids), ly = levels(iqs);
  auto nearest = [](const std::vector<double>& l, double v) {
    size_t best = 0;
    for (size_t k = 1; k < l.size(); ++k) if (std::abs(l[k] - v) < std::abs(l[best] - v)) best = k;
    return best;
  };
  std::vector<plot::Figure> panels;
  for (int p = 0; p < 2; ++p) {
    plot::Figure f(absl::StrFormat("residual-%s-%s", after ? "after" : "before", signals[p]), 560, 440);
    f.SetTitle(absl::StrFormat("%s (%s)", signals[p], what[p]));
    f.SetXLabel("id [A]");
    f.SetYLabel("iq [A]");
    plot::HeatOptions o;
    o.colour_label = "|z| [sigma]";
    o.class_bounds = {2, 5};
    o.class_colours = {"#88cc88", "#ffcc66", "#ee5555"};
    o.value_format = "%.1f";
    std::vector<double> z(lx.size() * ly.size(), std::nan(""));
    o.cell_titles.assign(z.size(), "");
    size_t points = 0, shared = 0;
    for (const auto& q : r.residuals) {
      if (q.speed_rpm != 0 || q.signal != signals[p]) continue;
      const double v = after ? q.after : q.before;
      const size_t k = nearest(ly, q.iq_a) * lx.size() + nearest(lx, q.id_a);
      ++points;
      // Two points in one cell (a repeated operating point): the cell
      // shows the worse, its tooltip names both.
      if (std::isfinite(z[k])) ++shared;
      z[k] = std::isfinite(z[k]) ? std::max(z[k], v) : v;
      o.cell_titles[k] += absl::StrFormat("%s%s %s: |z| = %.2f sigma (%s %.2f)", o.cell_titles[k].empty() ? "" : "; ",
                                          q.point, q.signal, v, after ? "before" : "after", after ? q.before : q.after);
    }
    if (points == 0) {
      f.Note("no standstill point of this signal");
    } else {
      f.Heatmap(lx, ly, z, std::move(o));
      if (shared > 0) f.Note(absl::StrFormat("%zu repeated points: a cell shows the larger |z|", shared));
    }
    panels.push_back(std::move(f));
  }
  return plot::PanelsSvg(absl::StrFormat("residual-%s", after ? "after" : "before"),
                         absl::StrFormat("%s: normalised residual |z| per standstill point, %s the findings (green "
                                         "< 2 sigma, amber < 5, red >= 5)",
                                         r.serial, after ? "after" : "before"),
                         panels, 2);
}

std::string SpectrumSvg(const DiagnosisReport& r) {
  plot::Figure f("replay-spectrum", 980, 560);
  f.SetTitle(absl::StrFormat("%s: spectrum of the replay residual (complex alpha-beta): %.3g A RMS with the nominal "
                             "model, %.3g A with the final one",
                             r.serial, r.waveform_rms_before_a, r.waveform_rms_after_a));
  f.SetXLabel("frequency [Hz]");
  f.SetYLabel("residual amplitude [A]");
  // Log axis over at most seven decades below the top: the final model's
  // broadband floor stays on it; bins even lower are marked on the floor.
  f.SetYLog(true, 7);
  // Below the axes: 2 x 101 bars need the width.
  f.SetLegendBelow(true);
  const size_t n = std::min({r.spectrum_hz.size(), r.spectrum_before_a.size(), r.spectrum_after_a.size()});
  if (n == 0) {
    f.SetXRange(-1, 1);
    f.Note("no replay: waveform evidence was not computed");
    return f.Svg();
  }
  const std::vector<double> hz(r.spectrum_hz.begin(), r.spectrum_hz.begin() + n);
  const std::vector<double> before(r.spectrum_before_a.begin(), r.spectrum_before_a.begin() + n);
  const std::vector<double> after(r.spectrum_after_a.begin(), r.spectrum_after_a.begin() + n);
  // Bin spacing: the pair of bars of a bin fills 80 % of it.
  double bin = 0;
  for (size_t k = 1; k < n; ++k) {
    const double d = std::abs(hz[k] - hz[k - 1]);
    if (d > 0 && (bin == 0 || d < bin)) bin = d;
  }
  if (bin == 0) bin = 1;
  plot::Style nominal, final_model;
  nominal.colour = "#cc3333";
  final_model.colour = "#3366cc";
  f.Bars(hz, before, 0.4 * bin, nominal, "nominal model (before)", -0.2 * bin);
  f.Bars(hz, after, 0.4 * bin, final_model, "final model (after)", 0.2 * bin);
  // Where a bin counts as standing out (docs/diagnosis.md): 10x (20 dB)
  // above the spectrum's own median bin.
  auto threshold = [](std::vector<double> v) {
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return 10.0 * v[v.size() / 2];
  };
  const double x0 = hz.front() - bin, x1 = hz.back() + bin;
  for (const auto& [v, st, who] : {std::tuple{&before, nominal, "nominal"}, std::tuple{&after, final_model, "final"}}) {
    plot::Style line = st;
    line.width_px = 1.2;
    line.dash = "6 3";
    const double t = threshold(*v);
    f.Line({x0, x1}, {t, t}, line, absl::StrFormat("%s: 20 dB above its median bin (%.2g A)", who, t));
  }
  f.SetXRange(x0, x1);
  f.SetTight(true, false);
  return f.Svg();
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
