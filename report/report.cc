#include "report/report.h"

#include <algorithm>
#include <cmath>
#include <ctime>
#include <map>

#include "absl/status/status.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "plot/plot.h"
#include "report/format.h"
#include "tables/export_rule.h"
#include "tables/tables.h"
#include "physics/speed.h"

namespace fluxcal::report {
namespace {


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

// A JSON value as text: strings unquoted (their numbers rounded, they were
// written by another program), numbers rounded by `r`, "" when absent.
std::string ValueText(const nlohmann::json& v, Rounding r = Rounding{4, 0}) {
  if (v.is_null()) return "";
  if (v.is_string()) return RoundNumbersInText(v.get<std::string>());
  if (v.is_number()) return Num(v.get<double>(), r);
  return RoundNumbersInText(v.dump());
}
std::string JsonText(const nlohmann::json& j, const char* key, Rounding r = Rounding{4, 0}) {
  if (!j.is_object() || !j.contains(key)) return "";
  return ValueText(j[key], r);
}
// A relative residual (0.0123) as a percentage ("1.2 %").
std::string PercentText(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key) || !j[key].is_number()) return JsonText(j, key);
  return Num(100 * j[key].get<double>(), kPercent, "%");
}

std::string Row(const std::string& k, const std::string& v) {
  return "<tr><th>" + H(k) + "</th><td>" + v + "</td></tr>\n";
}

// How a table axis or output named with its unit suffix is rounded.
Rounding RoundingOf(const std::string& name) {
  if (absl::EndsWith(name, "_a")) return kCurrentA;
  if (absl::EndsWith(name, "_nm")) return kTorqueNm;
  if (absl::EndsWith(name, "_rpm")) return kSpeedRpm;
  if (absl::EndsWith(name, "_wb")) return kFluxWb;
  if (absl::EndsWith(name, "_v")) return kVoltageV;
  return Rounding{4, 0};
}
std::string UnitOf(const std::string& name) {
  if (absl::EndsWith(name, "_a")) return "A";
  if (absl::EndsWith(name, "_nm")) return "N m";
  if (absl::EndsWith(name, "_rpm")) return "rpm";
  if (absl::EndsWith(name, "_wb")) return "Wb";
  if (absl::EndsWith(name, "_v")) return "V";
  return "";
}

// ---------------------------------------------------------------- coverage

// Where a value on the page comes from: the measured region, its mirror
// image (a model symmetric in iq: psi_d even, psi_q odd, so the unmeasured
// half is the measured one reflected), or the model's continuation beyond
// both. Every curve is drawn solid, dashed or dotted by it.
//
// The calibration keeps its region as |iq| and no flag says which half was
// measured; Coverage works that out below. When calibrations and tables
// carry a "by symmetry" flag of their own, Source comes from it and
// MeasuredCoverage shrinks to reading it.
enum class Source { kMeasured = 0, kMirror = 1, kExtrapolated = 2 };

const char* DashOf(Source s) {
  switch (s) {
    case Source::kMeasured: return "";
    case Source::kMirror: return "8 4";
    case Source::kExtrapolated: return "2 3";
  }
  return "";
}

struct Coverage {
  double id_lo = 0, id_hi = 0, iq_lo = 0, iq_hi = 0;   // the measured box, iq signed
  bool symmetric = true;                               // the model's family is mirror symmetric in iq
  std::string basis;                                   // how the box was found, said on the page
  bool InBox(double id, double iq) const {
    // The calibration's own margin (Calibration::InMeasuredRegion): 2 %.
    const double mi = 0.02 * (id_hi - id_lo + 1.0), mq = 0.02 * (iq_hi - iq_lo + 1.0);
    return id >= id_lo - mi && id <= id_hi + mi && iq >= iq_lo - mq && iq <= iq_hi + mq;
  }
  Source At(double id, double iq) const {
    if (InBox(id, iq)) return Source::kMeasured;
    if (symmetric && InBox(id, -iq)) return Source::kMirror;
    return Source::kExtrapolated;
  }
  bool MotoringMeasured() const { return iq_hi > 0.05 * std::max(std::abs(iq_lo), 1.0); }
  bool GeneratingMeasured() const { return iq_lo < -0.05 * std::max(std::abs(iq_hi), 1.0); }
  // What the unmeasured half is, in words.
  std::string OtherHalf() const {
    if (MotoringMeasured() && GeneratingMeasured()) return "Both halves measured";
    const char* missing = MotoringMeasured() ? "iq < 0 (generating)" : "iq > 0 (motoring)";
    return symmetric ? absl::StrCat(missing, ": by symmetry, the measured half mirrored (the model family is "
                                             "symmetric in iq)")
                     : absl::StrCat(missing, ": extrapolated (the model family is asymmetric in iq and nothing was "
                                             "measured there)");
  }
};

Coverage MeasuredCoverage(const fit::Calibration& cal, const fit::FitData* data) {
  Coverage c;
  const fit::Family& fam = cal.family();
  c.symmetric = !(fam.kind == fit::Family::kSpline && !fam.spline.Folded());
  c.id_lo = cal.id_min_a();
  c.id_hi = cal.id_max_a();
  c.iq_lo = cal.iq_min_a();
  c.iq_hi = cal.iq_max_a();
  if (data != nullptr) {
    double dl = 1e300, dh = -1e300, ql = 1e300, qh = -1e300;
    auto note = [&](double id, double iq) {
      dl = std::min(dl, id), dh = std::max(dh, id), ql = std::min(ql, iq), qh = std::max(qh, iq);
    };
    for (const auto& o : data->inductances) note(o.id_a, o.iq_a);
    for (const auto& o : data->steady_state) note(o.id_a, o.iq_a);
    for (const auto& o : data->fluxes) note(o.id_a, o.iq_a);
    if (dl <= dh) {
      c.id_lo = dl, c.id_hi = dh, c.iq_lo = ql, c.iq_hi = qh;
      c.basis = "the signed currents of the measured points given";
      return c;
    }
  }
  if (!c.symmetric && fam.spline.smoothing) {
    // An asymmetric smoothing spline's knots span the signed iq of its
    // data plus a margin m = 0.05 max(D, 10 A) on each side, D the data's
    // width including iq = 0 (fitting/fit.cc, smooth(false)): the width
    // W = D + 2 m gives m = W / 22 for D >= 10 A, else 0.5 A.
    const double w = fam.spline.iq_hi_a - fam.spline.iq_lo_a;
    const double m = w >= 11.0 ? w / 22.0 : 0.5;
    const double lo = fam.spline.iq_lo_a + m, hi = fam.spline.iq_hi_a - m;
    if (std::abs(std::max(-lo, hi) - cal.iq_max_a()) <= 1e-6 * std::max(1.0, cal.iq_max_a())) {
      c.iq_lo = lo < -1e-9 ? lo : cal.iq_min_a();
      c.iq_hi = hi > 1e-9 ? hi : -cal.iq_min_a();
      c.basis = "the asymmetric model's knot span (it covers the signed iq of the data it was fitted to)";
      return c;
    }
  }
  c.basis = c.symmetric ? "the calibration's region (it keeps |iq|; the model is symmetric in iq, so either half "
                          "shows the other)"
                        : "the calibration's region (it keeps |iq|: the measured half is taken to be iq > 0)";
  return c;
}

// Draws y(x) as runs of equal source: solid, dashed (mirror) or dotted
// (extrapolated), each run sharing its end sample with the next so the
// curve stays continuous. The label goes with the run of the best source
// present, so the legend shows the curve as it mostly is where measured.
// Returns a bit per source drawn.
unsigned LineBySource(plot::Figure* f, const std::vector<double>& x, const std::vector<double>& y,
                      const std::vector<Source>& src, plot::Style st, std::string label) {
  const size_t n = std::min({x.size(), y.size(), src.size()});
  unsigned drawn = 0;
  Source best = Source::kExtrapolated;
  for (size_t k = 0; k < n; ++k) {
    if (std::isfinite(y[k]) && src[k] < best) best = src[k];
  }
  size_t a = 0;
  while (a < n) {
    size_t b = a;
    while (b + 1 < n && src[b + 1] == src[a]) ++b;
    const size_t end = std::min(n - 1, b + 1);   // overlap one sample with the next run
    std::vector<double> xs(x.begin() + a, x.begin() + end + 1), ys(y.begin() + a, y.begin() + end + 1);
    plot::Style s = st;
    s.dash = DashOf(src[a]);
    const bool labelled = !label.empty() && src[a] == best;
    f->Line(xs, ys, s, labelled ? label : "");
    if (labelled) label.clear();
    drawn |= 1u << static_cast<int>(src[a]);
    a = b + 1;
  }
  return drawn;
}

// The legend's key to the line patterns, for the sources a figure drew.
void SourceKey(plot::Figure* f, unsigned drawn, const Coverage& cov) {
  if (drawn == 1u) return;   // all measured: nothing to tell apart
  plot::Style st;
  st.colour = "#666666";
  st.width_px = 1.6;
  if (drawn & 1u) f->Line({}, {}, st, "solid: in the measured region");
  if (drawn & 2u) {
    st.dash = DashOf(Source::kMirror);
    f->Line({}, {}, st, absl::StrCat("dashed: by symmetry (mirror of ", cov.MotoringMeasured() ? "iq > 0" : "iq < 0",
                                     ")"));
  }
  if (drawn & 4u) {
    st.dash = DashOf(Source::kExtrapolated);
    f->Line({}, {}, st, "dotted: extrapolated, not measured");
  }
}

// ------------------------------------------------------- positive definite

// Where the differential inductance is not positive definite (Ldd > 0,
// Lqq > 0, Ldd Lqq > Ldq^2: the condition of Calibration::PhysicalOver),
// on a grid over the region PhysicalOver(1.5) checks (the measured region
// widened 1.5x towards negative id and larger |iq|), both signs of iq.
struct PdScan {
  int nx = 31, ny = 61, nodes = 0, bad = 0;
  int bad_by_source[3] = {0, 0, 0};
  double id_lo = 0, id_hi = 0, q_max = 0;
  std::vector<double> bad_id, bad_iq;
};

PdScan ScanPositiveDefinite(const fit::Calibration& cal, const Coverage& cov) {
  PdScan s;
  s.id_lo = std::min(cal.id_min_a(), 0.0) * 1.5;
  s.id_hi = std::max(cal.id_max_a(), 0.0);
  s.q_max = std::max(cal.iq_max_a(), 1.0) * 1.5;
  for (double iq : Linspace(-s.q_max, s.q_max, s.ny)) {
    for (double id : Linspace(s.id_lo, s.id_hi, s.nx)) {
      ++s.nodes;
      const auto L = cal.Inductance(id, iq);
      if (L.ldd_h > 0 && L.lqq_h > 0 && L.ldd_h * L.lqq_h - L.ldq_h * L.ldq_h > 0) continue;
      ++s.bad;
      ++s.bad_by_source[static_cast<int>(cov.At(id, iq))];
      s.bad_id.push_back(id);
      s.bad_iq.push_back(iq);
    }
  }
  return s;
}

std::string PdText(const PdScan& s) {
  const std::string grid =
      absl::StrFormat("%d x %d grid over id %s, iq %s (the measured region widened 1.5x, both torque directions)",
                      s.nx, s.ny, Range(s.id_lo, s.id_hi, kCurrentA, "A"), Range(-s.q_max, s.q_max, kCurrentA, "A"));
  if (s.bad == 0) return absl::StrFormat("yes, at all %d nodes of a %s", s.nodes, grid);
  const auto [dl, dh] = std::minmax_element(s.bad_id.begin(), s.bad_id.end());
  const auto [ql, qh] = std::minmax_element(s.bad_iq.begin(), s.bad_iq.end());
  std::string t = absl::StrFormat(
      "no, at %d of %d nodes of a %s: where id %s and iq %s. Of them %d inside the measured region, %d in its mirror "
      "image, %d in the extrapolation.",
      s.bad, s.nodes, grid, Range(*dl, *dh, kCurrentA, "A"), Range(*ql, *qh, kCurrentA, "A"),
      s.bad_by_source[0], s.bad_by_source[1], s.bad_by_source[2]);
  if (s.bad_by_source[0] == 0) {
    absl::StrAppend(&t, " Inside the measured region the model is physical; the verdict judges the fit there and is "
                        "not affected. What is computed at those currents (table cells beyond the measured region) "
                        "rests on a continuation that no machine has. They are marked x on the current-plane figure.");
  } else {
    absl::StrAppend(&t, " The fitted surface is not a physical magnetic model inside the measured region at those "
                        "nodes (marked x on the current-plane figure); the verdict does not check this.");
  }
  return t;
}

// ------------------------------------------------------------- surfaces

// Curve families: the currents to draw curves for. From the measured
// points when there are any (so that dots and lines pair up; measured
// currents scatter around their set point, so values closer than 3 % of
// the range are one group), otherwise round values across the measured
// range; at most six magnitudes. Over iq the family holds both signs of
// each magnitude (the generating half is drawn too).
std::vector<double> Family(const fit::Calibration& cal, const fit::FitData* data, bool over_iq, const Coverage& cov) {
  const double lo = over_iq ? 0.0 : cal.id_min_a();
  const double hi = over_iq ? std::max(std::abs(cov.iq_lo), std::abs(cov.iq_hi)) : cal.id_max_a();
  std::vector<double> raw;
  if (data != nullptr) {
    auto take = [&](double id, double iq) { raw.push_back(over_iq ? std::abs(iq) : id); };
    for (const auto& o : data->inductances) take(o.id_a, o.iq_a);
    if (raw.empty()) for (const auto& o : data->fluxes) take(o.id_a, o.iq_a);
    if (raw.empty()) for (const auto& o : data->steady_state) take(o.id_a, o.iq_a);
  }
  std::vector<double> v;
  if (!raw.empty()) {
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
  if (!over_iq) return v;
  std::vector<double> signed_v;
  for (double m : v) {
    signed_v.push_back(m);
    if (m > 0) signed_v.push_back(-m);
  }
  return signed_v;
}

// Index of the family member an observed current belongs to, -1 if none:
// within `tol` (<= 0: half the smallest spacing, or 3 % of the range for
// a single member), the nearest.
int Member(const std::vector<double>& family, double value, double range, double tol = 0) {
  if (!(tol > 0)) {
    std::vector<double> sorted = family;
    std::sort(sorted.begin(), sorted.end());
    double spacing = range;
    for (size_t k = 1; k < sorted.size(); ++k) spacing = std::min(spacing, sorted[k] - sorted[k - 1]);
    tol = sorted.size() > 1 ? spacing / 2 : 0.03 * range;
  }
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
  void Figure(const plot::Figure& f, const std::string& caption) { Svg(f.Svg(), caption); }
  void Svg(const std::string& svg, const std::string& caption) {
    body += "<figure>" + svg + "<figcaption>" + caption + "</figcaption></figure>\n";
    ++figures;
  }
};

// Differential inductance or flux linkage against iq, one curve per id
// (psi_d against id, one curve per iq: its shape along id is the d-axis
// saturation), both torque directions; the measured points in the colour
// of their curve: identified inductances (+-1 sigma), the steady-state
// rows' flux (fit::SteadyStateFlux), a flux map's nodes.
enum class Quantity { kLdd, kLqq, kLdq, kPsiD, kPsiQ };

void QuantityFigure(Page* page, const fit::Calibration& cal, const fit::FitData* data, const Coverage& cov,
                    Quantity q) {
  const bool over_id = q == Quantity::kPsiD;   // x axis id, curves per iq
  const std::vector<double> fam = Family(cal, data, over_id, cov);
  const double q_abs = std::max({std::abs(cov.iq_lo), std::abs(cov.iq_hi), cal.iq_max_a()});
  const double x_lo = over_id ? cal.id_min_a() : -q_abs;
  const double x_hi = over_id ? cal.id_max_a() : q_abs;
  const auto xs = Linspace(x_lo, x_hi, 121);
  struct Spec { const char* id; const char* title; const char* symbol; const char* unit; };
  const Spec spec[] = {{"ldd", "Ldd = dpsi_d/did", "Ldd", "H"},
                       {"lqq", "Lqq = dpsi_q/diq", "Lqq", "H"},
                       {"ldq", "Ldq = dpsi_d/diq (cross saturation)", "Ldq", "H"},
                       {"psid", "flux linkage psi_d", "psi_d", "Wb"},
                       {"psiq", "flux linkage psi_q", "psi_q", "Wb"}};
  const Spec& sp = spec[static_cast<int>(q)];
  plot::Figure f(std::string("fig-") + sp.id, 640, 440);
  f.SetLegendBelow(true);
  f.SetTitle(sp.title);
  f.SetXLabel(over_id ? "id [A]" : "iq [A]");
  f.SetXRange(x_lo, x_hi);
  // The frame ends where the surface's region ends (e.g. id 0.16 A): a
  // whole-tick end would leave a band with nothing in it.
  f.SetTight(true, false);
  // The lines need no standard deviation: Flux and Inductance, not
  // Predict (which propagates the covariance at every sample). In SI here,
  // scaled to the unit shown below.
  auto value = [&](double id, double iq) {
    if (q == Quantity::kPsiD || q == Quantity::kPsiQ) {
      const auto p = cal.Flux(id, iq);
      return q == Quantity::kPsiD ? p.psi_d_wb : p.psi_q_wb;
    }
    const auto l = cal.Inductance(id, iq);
    return q == Quantity::kLdd ? l.ldd_h : q == Quantity::kLqq ? l.lqq_h : l.ldq_h;
  };
  std::vector<std::vector<double>> ys(fam.size());
  std::vector<std::vector<Source>> src(fam.size());
  double y_lo = 1e300, y_hi = -1e300;   // every sample
  double m_lo = 1e300, m_hi = -1e300;   // measured and mirrored samples
  for (size_t k = 0; k < fam.size(); ++k) {
    for (double x : xs) {
      const double id = over_id ? x : fam[k], iq = over_id ? fam[k] : x;
      const double y = value(id, iq);
      ys[k].push_back(y);
      src[k].push_back(cov.At(id, iq));
      y_lo = std::min(y_lo, y), y_hi = std::max(y_hi, y);
      if (src[k].back() != Source::kExtrapolated) m_lo = std::min(m_lo, y), m_hi = std::max(m_hi, y);
    }
  }
  if (m_lo > m_hi) m_lo = y_lo, m_hi = y_hi;   // nothing measured on these lines
  // The unit engineers quote: milli, or micro for a small machine's
  // inductance (0.17 mH reads 170 uH; a cross saturation of 0.3 uH would
  // read 0.0003 in mH).
  const double peak = std::max(std::abs(m_lo), std::abs(m_hi));
  const double scale = peak >= 1e-3 ? 1e3 : 1e6;
  const std::string unit = std::string(scale == 1e3 ? "m" : "u") + sp.unit;
  f.SetYLabel(absl::StrFormat("%s [%s]", sp.symbol, unit));
  for (auto& y : ys) {
    for (double& v : y) v *= scale;
  }
  y_lo *= scale, y_hi *= scale, m_lo *= scale, m_hi *= scale;
  // The view (set below): the measured span and as much again on either
  // side, within what the curves reach.
  const double view_span = m_hi - m_lo;
  const double view = std::max(std::min(y_hi, m_hi + view_span) - std::max(y_lo, m_lo - view_span),
                               1e-9 * std::max(1.0, std::abs(y_hi)));
  // Curves closer than about a pixel everywhere are one line with one
  // legend entry naming all their currents (psi_d at +-iq of a symmetric
  // model, psi_q at every id of a machine without cross saturation).
  const auto group = plot::CoincidentGroups(ys, 0.004 * view);
  // "0, ±20, ±40 A": a family's currents, each magnitude once when both
  // signs are there.
  auto currents = [over_id](std::vector<double> v) {
    if (over_id) {
      std::sort(v.begin(), v.end(), [](double a, double b) {
        return std::abs(a) < std::abs(b) || (std::abs(a) == std::abs(b) && a > b);
      });
    } else {
      std::sort(v.begin(), v.end());
    }
    std::vector<std::string> t;
    for (size_t i = 0; i < v.size(); ++i) {
      if (i + 1 < v.size() && v[i] > 0 && v[i + 1] == -v[i]) {
        t.push_back("±" + Num(v[i], kCurrentA));
        ++i;
      } else {
        t.push_back(Num(v[i], kCurrentA));
      }
    }
    return absl::StrJoin(t, ", ") + " A";
  };
  // One colour per magnitude: +-iq share theirs, told apart by the line.
  std::vector<double> mags;
  for (double v : fam) {
    if (std::none_of(mags.begin(), mags.end(), [&](double m) { return std::abs(m - std::abs(v)) < 1e-9; })) {
      mags.push_back(over_id ? std::abs(v) : v);
    }
  }
  auto colour_of = [&](size_t k) {
    const double m = over_id ? std::abs(fam[k]) : fam[k];
    for (size_t c = 0; c < mags.size(); ++c) {
      if (std::abs(mags[c] - m) < 1e-9) return plot::Palette(static_cast<int>(c));
    }
    return plot::Palette(0);
  };
  const char* name = over_id ? "iq" : "id";
  // Curves apart by more than a pixel but within 3 % of the range (six id
  // lines of psi_q on a machine with little cross saturation) read as one
  // band: a note names them and how far apart they are.
  std::vector<std::string> bands;
  {
    // 3 % of the view.
    const auto near = plot::CoincidentGroups(ys, 0.03 * view);
    for (size_t k = 0; k < fam.size(); ++k) {
      std::vector<size_t> members, leaders;
      for (size_t m = 0; m < fam.size(); ++m) {
        if (near[m] == k) members.push_back(m);
        if (near[m] == k && group[m] == m) leaders.push_back(m);
      }
      if (leaders.size() < 2) continue;
      double spread = 0;
      for (size_t i = 0; i < xs.size(); ++i) {
        double lo = 1e300, hi = -1e300;
        for (size_t m : members) lo = std::min(lo, ys[m][i]), hi = std::max(hi, ys[m][i]);
        spread = std::max(spread, hi - lo);
      }
      std::vector<double> t;
      for (size_t m : members) t.push_back(fam[m]);
      bands.push_back(absl::StrFormat("%s = %s lie within %s %s of each other", name, currents(t),
                                      Num(spread, Rounding{2, 0}), unit));
    }
  }
  unsigned drawn = 0;
  for (size_t k = 0; k < fam.size(); ++k) {
    if (group[k] != k) continue;
    std::vector<double> members;
    for (size_t m = 0; m < fam.size(); ++m) {
      if (group[m] == k) members.push_back(fam[m]);
    }
    const bool pair = members.size() == 2 && members[0] == -members[1];
    const std::string label =
        absl::StrFormat("%s = %s%s", name, currents(members), members.size() > 1 && !pair ? " (coincide)" : "");
    plot::Style st;
    st.colour = colour_of(k);
    drawn |= LineBySource(&f, xs, ys[k], src[k], st, label);
  }
  // Measured points, each in the colour of the curve of its current.
  const double fam_range = over_id ? 2 * q_abs : cal.id_max_a() - cal.id_min_a();
  std::vector<std::vector<double>> px(fam.size()), py(fam.size()), pe(fam.size());
  size_t n_ind = 0, n_ss = 0, n_map = 0;
  auto add = [&](double id, double iq, double x, double y, double e, double tol) {
    const int k = Member(fam, over_id ? iq : id, std::max(fam_range, 1.0), tol);
    if (k < 0) return false;
    const size_t g = group[k];
    px[g].push_back(x);
    py[g].push_back(scale * y);
    pe[g].push_back(scale * e);
    return true;
  };
  std::vector<double> ssx, ssy, mx, my;   // keep each kind's own marker apart: drawn after
  std::vector<size_t> ssg, mg;
  if (data != nullptr) {
    if (q == Quantity::kLdd || q == Quantity::kLqq || q == Quantity::kLdq) {
      for (const auto& o : data->inductances) {
        double v = 0, e = 0;
        if (q == Quantity::kLdd) v = o.ldd_h, e = o.ldd_h_std;
        if (q == Quantity::kLqq) v = o.lqq_h, e = o.lqq_h_std;
        if (q == Quantity::kLdq) {
          if (!o.ldq_h) continue;
          v = *o.ldq_h, e = o.ldq_h_std;
        }
        n_ind += add(o.id_a, o.iq_a, o.iq_a, v, e, 0);
      }
    } else {
      const bool d = q == Quantity::kPsiD;
      for (const auto& s : data->steady_state) {
        double pd = 0, pq = 0;
        fit::SteadyStateFlux(s, cal.pole_pairs(), data->rs_ohm ? data->rs_ohm : cal.rs_ohm(), data->f_pwm_hz, &pd, &pq);
        const int k = Member(fam, over_id ? s.iq_a : s.id_a, std::max(fam_range, 1.0));
        if (k < 0 || !std::isfinite(pd) || !std::isfinite(pq)) continue;
        ssx.push_back(over_id ? s.id_a : s.iq_a);
        ssy.push_back(scale * (d ? pd : pq));
        ssg.push_back(group[k]);
        ++n_ss;
      }
      // Map nodes lie on a grid: a node belongs to a curve only at its
      // exact current (1 % of the range), not to the nearest one.
      for (const auto& n : data->fluxes) {
        const int k = Member(fam, over_id ? n.iq_a : n.id_a, std::max(fam_range, 1.0), 0.01 * std::max(fam_range, 1.0));
        if (k < 0) continue;
        mx.push_back(over_id ? n.id_a : n.iq_a);
        my.push_back(scale * (d ? n.psi_d_wb : n.psi_q_wb));
        mg.push_back(group[k]);
        ++n_map;
      }
    }
  }
  for (size_t k = 0; k < fam.size(); ++k) {
    plot::Style st;
    st.colour = colour_of(k);
    if (!px[k].empty()) f.Scatter(px[k], py[k], st, "", pe[k]);
    for (size_t i = 0; i < py[k].size(); ++i) {
      m_lo = std::min(m_lo, py[k][i] - pe[k][i]), m_hi = std::max(m_hi, py[k][i] + pe[k][i]);
    }
  }
  for (const auto* v : {&ssy, &my}) {
    for (double y : *v) m_lo = std::min(m_lo, y), m_hi = std::max(m_hi, y);
  }
  // The view is the measured surface's (and the points'), with as much
  // room again as its span on either side: an extrapolation that runs away
  // (a spline's continuation) leaves the frame instead of flattening what
  // was measured.
  bool clipped = false;
  if (m_lo <= m_hi) {
    const double span = std::max(m_hi - m_lo, 1e-9 * std::max(1.0, std::abs(m_hi)));
    const double lo = std::max(y_lo, m_lo - span), hi = std::min(y_hi, m_hi + span);
    clipped = lo > y_lo || hi < y_hi;
    f.SetYRange(lo, hi);
  }
  auto scatter_kind = [&](const std::vector<double>& x, const std::vector<double>& y, const std::vector<size_t>& g,
                          double size_px) {
    for (size_t k = 0; k < fam.size(); ++k) {
      std::vector<double> a, b;
      for (size_t i = 0; i < x.size(); ++i) {
        if (g[i] == k) a.push_back(x[i]), b.push_back(y[i]);
      }
      if (a.empty()) continue;
      plot::Style st;
      st.colour = colour_of(k);
      st.marker_px = size_px;
      f.Scatter(a, b, st, "");
    }
  };
  scatter_kind(mx, my, mg, 2.2);
  scatter_kind(ssx, ssy, ssg, 4.2);
  plot::Style grey;
  grey.colour = "#555";
  if (n_ind > 0) f.Scatter({}, {}, grey, "identified, ±1 sigma");
  if (n_ss > 0) {
    grey.marker_px = 4.2;
    f.Scatter({}, {}, grey, "steady-state rows");
  }
  if (n_map > 0) {
    grey.marker_px = 2.2;
    f.Scatter({}, {}, grey, "flux map nodes");
  }
  SourceKey(&f, drawn, cov);
  if (clipped) f.Note("extrapolated stretches beyond the view are cut at the frame");
  for (const auto& band : bands) f.Note(band);
  std::vector<std::string> dots;
  if (n_ind > 0) dots.push_back(absl::StrFormat("%zu identified inductances (±1 sigma)", n_ind));
  if (n_ss > 0) {
    dots.push_back(absl::StrFormat("%zu steady-state rows' flux (psi_d = (uq - Rs iq) / w, psi_q = -(ud - Rs id) / w, "
                                   "delay-corrected: fit::SteadyStateFlux)", n_ss));
  }
  if (n_map > 0) dots.push_back(absl::StrFormat("%zu flux map nodes", n_map));
  page->Figure(f, absl::StrCat(
                      H(sp.title), " of ", H(cal.serial()), " from the fitted surface, one line per ", name,
                      " (curves within a pixel of each other drawn once, their entry names all)",
                      dots.empty() ? std::string(".")
                                   : absl::StrCat("; dots: ", H(absl::StrJoin(dots, ", ")),
                                                  ", in the colour of their ", name, "'s line."),
                      (drawn & 6u) ? absl::StrCat(" ", H(cov.OtherHalf()), ".") : std::string()));
}

double SpeedRpm(double we_rad_s, int pole_pairs) { return physics::ElectricalRadSToRpm(we_rad_s, pole_pairs); }

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

absl::StatusOr<Report> BuildReport(const ReportInputs& in) {
  if (in.calibration == nullptr) return absl::InvalidArgumentError("calibration: missing");
  const fit::Calibration& cal = *in.calibration;
  if (in.diagnosis && in.diagnosis->value("format", "") != "fluxcal.diagnosis.v1") {
    return absl::InvalidArgumentError(
        absl::StrCat(in.diagnosis_path, ": field 'format': expected 'fluxcal.diagnosis.v1'"));
  }
  Report rep;
  Page page;

  // Limits by the export rule (tables/export_rule.h), so the checksums on
  // this page are the ones an export with the same Udc prints. Udc: the
  // caller's (--udc-v, a set's manifest), else the calibration's; none is
  // ever assumed.
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
  const tables::MachineLimits lim = resolved->limits;
  const std::string i_max_source = resolved->i_max_source;
  const std::string udc_source =
      in.udc_v ? in.udc_source : "the calibration (drive.udc_v of the set it was fitted from)";
  const Coverage cov = MeasuredCoverage(cal, in.identified);
  // The voltage limit needs Udc and Rs; without either the page says so
  // instead of drawing one at some default.
  const bool voltage = lim.HasVoltageLimit();
  std::string no_voltage;
  if (!voltage) {
    no_voltage = absl::StrCat(
        "The voltage limit and the field-weakening map cannot be drawn: ",
        !lim.udc_v ? "the DC-link voltage Udc is not known (give --udc-v, or --set with a manifest that has "
                     "drive.udc_v)"
                   : "",
        !lim.udc_v && !lim.rs_ohm ? ", and " : "",
        !lim.rs_ohm ? "the calibration states no stator resistance Rs (its set's manifest has no motor.rs_ohm)" : "",
        ".");
  }
  tables::TableSpec spec;
  spec.serial = cal.serial();
  spec.calibration_version = cal.version;
  spec.model = cal.family().Name();
  spec.measured_current_limit_a = cal.MeasuredCurrentLimitA();
  std::map<std::string, tables::Table> tabs;
  std::string mtpv_note;
  bool mtpv_extrapolated = false;
  for (const char* kind : {"mtpa", "mtpv", "fw"}) {
    if (std::string(kind) == "fw" && !voltage) continue;
    spec.kind = kind;
    spec.allow_extrapolation = false;
    auto t = tables::BuildTable(cal, lim, spec);
    if (!t.ok() && std::string(kind) == "mtpv" && absl::IsFailedPrecondition(t.status())) {
      // No MTPV point inside the measured current limit: the export refuses
      // it; the page still draws it, computed in extrapolated magnetics and
      // said so (cells flagged, as `export --allow-extrapolation` would).
      spec.allow_extrapolation = true;
      t = tables::BuildTable(cal, lim, spec);
      mtpv_extrapolated = true;
      mtpv_note = std::string(
          "The MTPV curve lies beyond the measured current limit: drawn from the calibration's continuation "
          "(extrapolated, dotted); `fluxcal export --table mtpv` refuses it without --allow-extrapolation.");
    }
    if (!t.ok()) {
      return absl::InvalidArgumentError(absl::StrCat(in.calibration_path, ": ", kind, " table: ", t.status().message()));
    }
    tabs[kind] = std::move(*t);
  }
  const auto& mtpa = tabs["mtpa"];
  const auto& mtpv = tabs["mtpv"];

  // Base speed: where the MTPA point of the largest motoring torque meets
  // the voltage limit (bisection; the voltage grows with speed there).
  size_t kmax = 0;
  for (size_t k = 0; k < mtpa.axes[0].values.size(); ++k) {
    if (mtpa.axes[0].values[k] > mtpa.axes[0].values[kmax]) kmax = k;
  }
  const double id_b = mtpa.outputs[0].values[kmax], iq_b = mtpa.outputs[1].values[kmax];
  double base_rpm = 0, ell_rpm = 0;
  std::string ell_source, limits_warning;
  if (voltage) {
    double we_lo = 0, we_hi = 1e6;
    if (tables::VoltageV(cal, lim, id_b, iq_b, we_hi) < lim.UMaxV()) we_lo = we_hi;
    for (int k = 0; k < 80 && we_lo < we_hi; ++k) {
      const double mid = 0.5 * (we_lo + we_hi);
      (tables::VoltageV(cal, lim, id_b, iq_b, mid) < lim.UMaxV() ? we_lo : we_hi) = mid;
    }
    base_rpm = SpeedRpm(we_lo, lim.pole_pairs);
    ell_rpm = in.ellipse_speed_rpm;
    ell_source = "given (--speed-rpm)";
    if (!(ell_rpm > 0)) {
      // 1.5 x base speed, to two significant digits: far enough into field
      // weakening that the limit cuts the current circle.
      const double raw = 1.5 * base_rpm;
      const double mag = std::pow(10.0, std::floor(std::log10(std::max(raw, 1.0))) - 1);
      ell_rpm = std::round(raw / mag) * mag;
      ell_source = absl::StrFormat("1.5 x base speed %s, rounded", Num(base_rpm, kSpeedRpm, "rpm"));
    }
    // At standstill the voltage is Rs |i|: when that alone exceeds u_max the
    // limits are not the machine's (a wrong Udc) and the field-weakening map
    // is clamped everywhere. Said at the top.
    const double standstill_v = tables::VoltageV(cal, lim, id_b, iq_b, 0.0);
    if (!(base_rpm > 0) || standstill_v >= lim.UMaxV()) {
      limits_warning = absl::StrFormat(
          "The voltage limit u_max = %s (Udc %s: %s) is below the resistive drop at full MTPA current "
          "(%s at standstill): there is no base speed, and the field-weakening table is clamped at every "
          "speed. Check the machine's DC-link voltage (--udc-v, or a set whose manifest has drive.udc_v).",
          Num(lim.UMaxV(), kVoltageV, "V"), Num(*lim.udc_v, kVoltageV, "V"), udc_source,
          Num(standstill_v, kVoltageV, "V"));
    }
  }
  rep.ellipse_speed_rpm = ell_rpm;
  const double ell_we = physics::RpmToElectricalRadS(ell_rpm, lim.pole_pairs);
  const PdScan pd = ScanPositiveDefinite(cal, cov);

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

  // ------------------------------------------------------------ fit
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

  // ------------------------------------------------------------ surfaces
  b += "<section><h2>Inductances and flux linkages</h2><div class=\"grid\">\n";
  for (Quantity q : {Quantity::kLdd, Quantity::kLqq, Quantity::kLdq, Quantity::kPsiD, Quantity::kPsiQ}) {
    QuantityFigure(&page, cal, in.identified, cov, q);
  }
  b += "</div></section>\n";

  // ------------------------------------------------------------ current plane
  b += "<section><h2>Operating limits: MTPA, MTPV, current and voltage limit</h2>\n";
  {
    const double im = lim.i_max_a;
    plot::Figure f("fig-plane", 1000, 1000);
    f.SetTitle(voltage ? absl::StrFormat("MTPA and MTPV on the current plane, both torque directions (voltage limit at %s)",
                                         Num(ell_rpm, kSpeedRpm, "rpm"))
                       : std::string("MTPA and MTPV on the current plane, both torque directions (no voltage limit: "
                                     "Udc or Rs not known)"));
    f.SetXLabel("id [A]");
    f.SetYLabel("iq [A]");
    // Wide enough for the MTPV points near the current limit (up to
    // 1.6 i_max); rows farther out are counted in the legend instead.
    double mtpv_id_min = -1.2 * im;
    for (size_t k = 0; k < mtpv.outputs[0].values.size(); ++k) {
      const double d = mtpv.outputs[0].values[k];
      if (mtpv.outputs[2].values[k] > 0 && d >= -1.6 * im) mtpv_id_min = std::min(mtpv_id_min, d);
    }
    const double view_x_lo = mtpv_id_min, view_y = 1.2 * im;
    f.SetXRange(view_x_lo, 0.1 * im);
    f.SetYRange(-view_y, view_y);
    f.SetEqualAspect(true);
    f.SetTight(true, true);
    // Torque contours, current circle and voltage limit: the same drawing
    // as the exported MTPA / MTPV figures (tables::DrawCurrentPlane), over
    // both halves.
    tables::DrawCurrentPlane(&f, cal, lim, -2.5 * im, 2.5 * im, ell_we,
                             absl::StrFormat("voltage limit |u| = %s at %s", Num(lim.UMaxV(), kVoltageV, "V"),
                                             Num(ell_rpm, kSpeedRpm, "rpm")),
                             /*generating=*/true);
    plot::Style region;
    region.colour = "#2ca02c";
    region.width_px = 1.2;
    region.dash = "1 3";
    auto box = [&](double q0, double q1, const plot::Style& st, const std::string& label) {
      f.Line({cov.id_lo, cov.id_hi, cov.id_hi, cov.id_lo, cov.id_lo}, {q0, q0, q1, q1, q0}, st, label);
    };
    box(cov.iq_lo, cov.iq_hi, region,
        absl::StrFormat("measured region (id %s, iq %s)", Range(cov.id_lo, cov.id_hi, kCurrentA, "A"),
                        Range(cov.iq_lo, cov.iq_hi, kCurrentA, "A")));
    if (cov.symmetric && !(cov.MotoringMeasured() && cov.GeneratingMeasured())) {
      plot::Style mirror = region;
      mirror.colour = "#98df8a";
      mirror.dash = "4 4";
      box(-cov.iq_hi, -cov.iq_lo, mirror, "its mirror image (by symmetry)");
    }
    unsigned drawn = 0;
    // A table's rows as a curve through the plane, each stretch drawn by
    // where its rows lie (measured / mirror / extrapolated).
    auto curve = [&](const std::vector<double>& x, const std::vector<double>& y, const std::string& colour,
                     std::string label) -> bool {
      if (x.empty()) return false;   // nothing to draw: the caption says so
      size_t beyond = 0, outside = 0;
      std::vector<Source> src;
      for (size_t k = 0; k < x.size(); ++k) {
        beyond += x[k] < view_x_lo || std::abs(y[k]) > view_y;
        src.push_back(cov.At(x[k], y[k]));
        outside += src.back() == Source::kExtrapolated;
      }
      (void)outside;   // the line's pattern shows it; the caption says why
      label += beyond > 0 ? absl::StrFormat(", %zu beyond the view)", beyond) : std::string(")");
      plot::Style st;
      st.colour = colour;
      st.width_px = 2.5;
      drawn |= LineBySource(&f, x, y, src, st, label);
      return true;
    };
    // MTPA: every row, generating (iq < 0) to motoring, in torque order.
    curve(mtpa.outputs[0].values, mtpa.outputs[1].values, "#d62728",
          absl::StrFormat("MTPA (table: %zu rows", mtpa.outputs[0].values.size()));
    // MTPV: the table's rows (motoring only); rows the solver could not
    // place (no torque, or id at its search bound of -2 i_max) are not
    // points of the curve.
    std::vector<double> vx, vy;
    for (size_t k = 0; k < mtpv.outputs[0].values.size(); ++k) {
      if (!(mtpv.outputs[2].values[k] > 0) || mtpv.outputs[0].values[k] < -1.99 * im) continue;
      vx.push_back(mtpv.outputs[0].values[k]);
      vy.push_back(mtpv.outputs[1].values[k]);
    }
    const bool have_mtpv = curve(vx, vy, "#1f77b4", absl::StrFormat("MTPV (table: %zu rows", vx.size()));
    std::string mtpv_generating;
    if (have_mtpv && cov.symmetric) {
      // The table holds the motoring rows; a symmetric model's generating
      // MTPV is their mirror image.
      std::vector<double> my;
      for (double q : vy) my.push_back(-q);
      std::vector<Source> src;
      for (size_t k = 0; k < vx.size(); ++k) src.push_back(cov.At(vx[k], my[k]));
      plot::Style st;
      st.colour = "#1f77b4";
      st.width_px = 2.5;
      drawn |= LineBySource(&f, vx, my, src, st, "MTPV, generating: the table's rows mirrored");
      mtpv_generating = " The generating MTPV is the table's rows mirrored (the model is symmetric in iq).";
    } else if (have_mtpv) {
      f.Note("generating MTPV: not in the table");
      mtpv_generating = " The MTPV table holds motoring rows only; this model is asymmetric in iq, so its generating "
                        "MTPV is not their mirror image and is not drawn.";
    }
    if (pd.bad > 0) {
      plot::Style x;
      x.marker = plot::Marker::kCross;
      x.colour = "#7f7f7f";
      x.marker_px = 2.5;
      f.Scatter(pd.bad_id, pd.bad_iq, x, absl::StrFormat("not positive definite (%d grid nodes)", pd.bad));
    }
    SourceKey(&f, drawn, cov);
    const std::string voltage_text =
        voltage ? absl::StrFormat("the voltage limit |u| = %s (m Udc / sqrt 3, Udc %s) at %s (%s), ",
                                  Num(lim.UMaxV(), kVoltageV, "V"), Num(*lim.udc_v, kVoltageV, "V"),
                                  Num(ell_rpm, kSpeedRpm, "rpm"), H(ell_source))
                : std::string("no voltage limit (Udc or Rs not known: see above), ");
    const std::string base_text =
        voltage ? absl::StrFormat(" Base speed at full MTPA torque: %s.", Num(base_rpm, kSpeedRpm, "rpm")) : std::string();
    page.Figure(f, absl::StrCat(
                       "Constant-torque contours from the fitted flux linkage (T = 1.5 p (psi_d iq - psi_q id)), the "
                       "current limit, ", voltage_text, "and the MTPA and MTPV tables' rows, motoring (iq > 0) and "
                       "generating (iq < 0). ", H(cov.OtherHalf()), ".", base_text, H(mtpv_generating),
                       mtpv_extrapolated ? " " + H(mtpv_note) : std::string(),
                       have_mtpv ? "" : " The MTPV table has no row with positive torque to draw."));
  }
  b += "</section>\n";

  // ------------------------------------------------------------ envelope
  // The torque-speed envelope of the tables library (the `fluxcal export
  // --table envelope` table, tables::BuildTable kind "envelope"), over the
  // field-weakening table's speeds: at each speed the largest torque within
  // both limits, motoring (tm) and generating (tg), and where its operating
  // point lies.
  std::vector<double> env_n, tm, tg;
  std::vector<Source> sm, sg;
  if (voltage) {
    tables::TableSpec es = spec;
    es.kind = "envelope";
    es.allow_extrapolation = false;
    for (const bool generating : {false, true}) {
      es.envelope_generating = generating;
      auto env = tables::BuildTable(cal, lim, es);
      if (!env.ok()) {
        return absl::InvalidArgumentError(
            absl::StrCat(in.calibration_path, ": envelope table: ", env.status().message()));
      }
      env_n = env->axes[0].values;
      auto& t = generating ? tg : tm;
      auto& src = generating ? sg : sm;
      t.assign(env_n.size(), 0.0);
      src.assign(env_n.size(), Source::kMeasured);
      for (size_t j = 0; j < env_n.size(); ++j) {
        t[j] = env->outputs[2].values[j];
        src[j] = cov.At(env->outputs[0].values[j], env->outputs[1].values[j]);
      }
    }
  }

  b += "<section><h2>Torque-speed envelope</h2>\n";
  if (!voltage) {
    b += "<p>" + H(no_voltage) + "</p>\n";
  } else {
    b += "<div class=\"grid\">\n";
    const auto& n = env_n;
    unsigned drawn = 0;
    plot::Figure ft("fig-envelope-torque", 640, 420);
    ft.SetTitle("torque-speed envelope (limit torque)");
    ft.SetXLabel("speed [rpm]");
    ft.SetYLabel("torque [N m]");
    plot::Figure fp("fig-envelope-power", 640, 420);
    fp.SetTitle("power at the limit torque");
    fp.SetXLabel("speed [rpm]");
    fp.SetYLabel("mechanical power [kW]");
    for (plot::Figure* f : {&ft, &fp}) {
      f->SetXRange(n.front(), n.back());
      f->SetTight(true, false);
      f->SetLegendBelow(true);
    }
    std::vector<double> pm, pg;
    for (size_t j = 0; j < n.size(); ++j) {
      // P = T w_mech, w_mech = 2 pi n / 60.
      pm.push_back(tm[j] * physics::RpmToMechanicalRadS(n[j]) / 1e3);
      pg.push_back(tg[j] * physics::RpmToMechanicalRadS(n[j]) / 1e3);
    }
    plot::Style motor, gen;
    motor.colour = "#d62728";
    motor.width_px = 2.2;
    gen.colour = "#1f77b4";
    gen.width_px = 2.2;
    drawn |= LineBySource(&ft, n, tm, sm, motor, "motoring");
    drawn |= LineBySource(&ft, n, tg, sg, gen, "generating");
    LineBySource(&fp, n, pm, sm, motor, "motoring");
    LineBySource(&fp, n, pg, sg, gen, "generating");
    double t_top = 0, p_top = 0;
    for (size_t j = 0; j < n.size(); ++j) {
      t_top = std::max({t_top, std::abs(tm[j]), std::abs(tg[j])});
      p_top = std::max({p_top, std::abs(pm[j]), std::abs(pg[j])});
    }
    plot::Style base;
    base.colour = "#555555";
    base.width_px = 1;
    base.dash = "9 3 2 3";
    const std::string base_label = absl::StrFormat("base speed %s", Num(base_rpm, kSpeedRpm, "rpm"));
    if (base_rpm > 0 && base_rpm < n.back()) {
      ft.Line({base_rpm, base_rpm}, {-1.05 * t_top, 1.05 * t_top}, base, base_label);
      fp.Line({base_rpm, base_rpm}, {-1.05 * p_top, 1.05 * p_top}, base, base_label);
    }
    SourceKey(&ft, drawn, cov);
    SourceKey(&fp, drawn, cov);
    const std::string cap = absl::StrFormat(
        "At each speed of the field-weakening table (%s .. %s, %zu speeds), the largest torque within the current "
        "limit %s and the voltage limit %s (Udc %s): the envelope table (fluxcal export --table envelope), the "
        "limit the field-weakening table clamps to; MTPA below base speed, field weakening and MTPV above.",
        Num(n.front(), kSpeedRpm), Num(n.back(), kSpeedRpm, "rpm"), n.size(), Num(lim.i_max_a, kCurrentA, "A"),
        Num(lim.UMaxV(), kVoltageV, "V"), Num(*lim.udc_v, kVoltageV, "V"));
    page.Figure(ft, H(cap) + ((drawn & 6u) ? " " + H(cov.OtherHalf()) + "." : ""));
    page.Figure(fp, "Mechanical power P = T 2 pi n / 60 at the limit torque of the figure beside it.");
    b += "</div>\n";
  }
  b += "</section>\n";

  // ------------------------------------------------------------ fw maps
  b += "<section><h2>Field-weakening map</h2><div class=\"grid\">\n";
  if (!voltage) {
    b += "<p>" + H(no_voltage) + "</p>\n";
  } else {
    const auto& fw = tabs["fw"];
    const auto& tq = fw.axes[0].values;
    const auto& n = fw.axes[1].values;
    // Where each cell's operating point lies. When the cells off the
    // measured region are exactly the rows of one torque direction (a set
    // measured motoring only), a line at T = 0 and a note say so; else
    // each such cell gets a marker.
    std::vector<Source> cell_src(fw.outputs[0].values.size());
    size_t off = 0, off_gen = 0, gen_cells = 0, off_mirror = 0;
    for (size_t i = 0; i < tq.size(); ++i) {
      for (size_t j = 0; j < n.size(); ++j) {
        const size_t c = i * n.size() + j;
        cell_src[c] = cov.At(fw.outputs[0].values[c], fw.outputs[1].values[c]);
        const bool gen = tq[i] < 0;
        gen_cells += gen;
        if (cell_src[c] != Source::kMeasured) {
          ++off;
          off_gen += gen;
          off_mirror += cell_src[c] == Source::kMirror;
        }
      }
    }
    // (Rows next to T = 0 operate near iq = 0, inside the measured box.)
    const bool whole_half =
        off > 0 && off == off_gen && off_gen >= 0.9 * gen_cells && (off_mirror == 0 || off_mirror == off);
    const double cell_px = std::min(0.75 * 640 / n.size(), 0.75 * 420 / tq.size());
    const double marker = std::clamp(0.3 * cell_px, 1.5, 3.5);
    for (size_t o = 0; o < fw.outputs.size(); ++o) {
      const auto& out = fw.outputs[o];
      const std::string quantity = out.name == "id_a" ? "id" : "iq";
      plot::Figure f("fig-fw-" + out.name, 640, 440);
      f.SetTitle(absl::StrFormat("field weakening: %s", quantity));
      f.SetXLabel("speed [rpm]");
      f.SetYLabel("torque request [N m]");
      f.SetLegendBelow(true);
      plot::HeatOptions opt;
      opt.colour_label = quantity + " [A]";
      std::vector<double> cx, cy, ex, ey;
      for (size_t i = 0; i < tq.size(); ++i) {
        for (size_t j = 0; j < n.size(); ++j) {
          const size_t c = i * n.size() + j;
          opt.cell_titles.push_back(absl::StrFormat("%s, %s: %s = %s%s", Num(tq[i], kTorqueNm, "N m"),
                                                    Num(n[j], kSpeedRpm, "rpm"), quantity,
                                                    Num(out.values[c], kCurrentA, "A"),
                                                    fw.clamped[c] ? ", clamped" : ""));
          if (fw.clamped[c]) cx.push_back(n[j]), cy.push_back(tq[i]);
          if (!whole_half && cell_src[c] != Source::kMeasured) ex.push_back(n[j]), ey.push_back(tq[i]);
        }
      }
      f.Heatmap(n, tq, out.values, std::move(opt));
      // The limit torque per speed (the envelope): requests beyond it are
      // clamped to it. One line instead of a marker on every clamped cell.
      plot::Style under, over;
      under.colour = "#000000";
      under.width_px = 3.4;
      over.colour = "#ffffff";
      over.width_px = 1.4;
      // Where the limit lies beyond the table's torque axis (the cells' outer
      // edges), the line breaks: no request row reaches it there.
      const double half = tq.size() > 1 ? 0.5 * (tq[1] - tq[0]) : 0.5;
      for (const auto* t : {&tm, &tg}) {
        std::vector<double> y = *t;
        for (double& v : y) {
          if (v < tq.front() - half || v > tq.back() + half) v = std::nan("");
        }
        f.Line(n, y, under, "");
        f.Line(n, y, over, "");
      }
      plot::Style key = under;
      key.width_px = 2.4;
      if (!cx.empty()) {
        f.Line({}, {}, key, absl::StrFormat("limit torque: requests beyond it are clamped (%zu of %zu cells)",
                                            cx.size(), fw.clamped.size()));
      } else {
        f.Line({}, {}, key, "limit torque: no request row reaches it (no clamped cell)");
      }
      if (!ex.empty()) {
        plot::Style sq;
        sq.marker = plot::Marker::kSquare;
        sq.colour = "#ffffff";
        sq.halo = "#000000";
        sq.marker_px = marker;
        f.Scatter(ex, ey, sq, absl::StrFormat("operating point outside the measured region (%zu cells)", ex.size()));
      }
      if (whole_half) {
        plot::Style zero;
        zero.colour = "#ffffff";
        zero.width_px = 1.5;
        zero.dash = "6 3";
        f.Line({n.front(), n.back()}, {0, 0}, zero, "");
        f.Note(absl::StrFormat("below T = 0 (dashed): generating rows, %s",
                               off_mirror > 0 ? "by symmetry (mirror of the measured half)"
                                              : "extrapolated (iq < 0 not measured)"));
      }
      page.Figure(f, absl::StrFormat("The fw table's %s (%zu torque rows x %zu speeds, %s) from the tables library; "
                                     "the black-and-white line is the limit torque at each speed (the envelope): "
                                     "cells beyond it hold the limit point.",
                                     H(out.name), tq.size(), n.size(), H(Range(n.front(), n.back(), kSpeedRpm, "rpm"))));
    }
  }
  b += "</div></section>\n";

  // ------------------------------------------------------------ tables
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
    const auto& t = tabs[kind];
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

  // ------------------------------------------------------------ fleet
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
    for (const auto& fig : in.diagnosis_figures) page.Svg(fig.svg, H(fig.caption));
    b += "</section>\n";
  }

  static const char* kCss = R"css(
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
  rep.figures = page.figures;
  rep.html = "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n<title>fluxcal report " + H(cal.serial()) +
             absl::StrFormat(" v%d", cal.version) + "</title>\n<style>" + kCss + "</style></head>\n<body>\n" + page.body +
             "</body></html>\n";
  return rep;
}

}  // namespace fluxcal::report
