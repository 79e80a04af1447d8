// One figure of the page's "Inductances and flux linkages" section per
// quantity: a differential inductance or flux linkage of the fitted
// surface as a family of curves over the current plane, with the measured
// points over them in the colour of their curve.
#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "plot/plot.h"
#include "report/format.h"
#include "report/internal.h"

namespace fluxcal::report::internal {
namespace {

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

// Differential inductance or flux linkage against iq, one curve per id
// (psi_d against id, one curve per iq: its shape along id is the d-axis
// saturation), both torque directions; the measured points in the colour
// of their curve: identified inductances (+-1 sigma), the steady-state
// rows' flux (fit::SteadyStateFlux), a flux map's nodes.
enum class Quantity { kLdd, kLqq, kLdq, kPsiD, kPsiQ };

struct Spec { const char* id; const char* title; const char* symbol; const char* unit; };

const Spec& SpecOf(Quantity q) {
  static const Spec spec[] = {{"ldd", "Ldd = dpsi_d/did", "Ldd", "H"},
                              {"lqq", "Lqq = dpsi_q/diq", "Lqq", "H"},
                              {"ldq", "Ldq = dpsi_d/diq (cross saturation)", "Ldq", "H"},
                              {"psid", "flux linkage psi_d", "psi_d", "Wb"},
                              {"psiq", "flux linkage psi_q", "psi_q", "Wb"}};
  return spec[static_cast<int>(q)];
}

// The family's curves sampled along x and scaled to the unit shown, the
// spans the view is set from, and which curves coincide.
struct Curves {
  bool over_id = false;   // x axis id, curves per iq
  std::vector<double> fam, xs;
  std::vector<std::vector<double>> ys;
  std::vector<std::vector<Source>> src;
  double y_lo = 1e300, y_hi = -1e300;   // every sample
  double m_lo = 1e300, m_hi = -1e300;   // measured and mirrored samples
  double scale = 1;
  std::string unit;
  double view = 0;
  std::vector<size_t> group;   // the curve each one is drawn as
};

Curves SampleCurves(const fit::Calibration& cal, const Coverage& cov, Quantity q, const std::vector<double>& fam,
                    const std::vector<double>& xs) {
  Curves c;
  c.over_id = q == Quantity::kPsiD;
  c.fam = fam;
  c.xs = xs;
  const bool over_id = c.over_id;
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
  c.ys.resize(fam.size());
  c.src.resize(fam.size());
  for (size_t k = 0; k < fam.size(); ++k) {
    for (double x : xs) {
      const double id = over_id ? x : fam[k], iq = over_id ? fam[k] : x;
      const double y = value(id, iq);
      c.ys[k].push_back(y);
      c.src[k].push_back(cov.At(id, iq));
      c.y_lo = std::min(c.y_lo, y), c.y_hi = std::max(c.y_hi, y);
      if (c.src[k].back() != Source::kExtrapolated) c.m_lo = std::min(c.m_lo, y), c.m_hi = std::max(c.m_hi, y);
    }
  }
  if (c.m_lo > c.m_hi) c.m_lo = c.y_lo, c.m_hi = c.y_hi;   // nothing measured on these lines
  // The unit engineers quote: milli, or micro for a small machine's
  // inductance (0.17 mH reads 170 uH; a cross saturation of 0.3 uH would
  // read 0.0003 in mH).
  const double peak = std::max(std::abs(c.m_lo), std::abs(c.m_hi));
  c.scale = peak >= 1e-3 ? 1e3 : 1e6;
  c.unit = std::string(c.scale == 1e3 ? "m" : "u") + SpecOf(q).unit;
  for (auto& y : c.ys) {
    for (double& v : y) v *= c.scale;
  }
  c.y_lo *= c.scale, c.y_hi *= c.scale, c.m_lo *= c.scale, c.m_hi *= c.scale;
  // The view (set below): the measured span and as much again on either
  // side, within what the curves reach.
  const double view_span = c.m_hi - c.m_lo;
  c.view = std::max(std::min(c.y_hi, c.m_hi + view_span) - std::max(c.y_lo, c.m_lo - view_span),
                    1e-9 * std::max(1.0, std::abs(c.y_hi)));
  // Curves closer than about a pixel everywhere are one line with one
  // legend entry naming all their currents (psi_d at +-iq of a symmetric
  // model, psi_q at every id of a machine without cross saturation).
  c.group = plot::CoincidentGroups(c.ys, 0.004 * c.view);
  return c;
}

// "0, ±20, ±40 A": a family's currents, each magnitude once when both
// signs are there.
std::string CurrentsText(bool over_id, std::vector<double> v) {
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
}

// One colour per magnitude: +-iq share theirs, told apart by the line.
class Colours {
 public:
  Colours(const std::vector<double>& fam, bool over_id) : fam_(fam), over_id_(over_id) {
    for (double v : fam) {
      if (std::none_of(mags_.begin(), mags_.end(), [&](double m) { return std::abs(m - std::abs(v)) < 1e-9; })) {
        mags_.push_back(over_id ? std::abs(v) : v);
      }
    }
  }
  std::string operator()(size_t k) const {
    const double m = over_id_ ? std::abs(fam_[k]) : fam_[k];
    for (size_t c = 0; c < mags_.size(); ++c) {
      if (std::abs(mags_[c] - m) < 1e-9) return plot::Palette(static_cast<int>(c));
    }
    return plot::Palette(0);
  }

 private:
  const std::vector<double>& fam_;
  bool over_id_;
  std::vector<double> mags_;
};

// Curves apart by more than a pixel but within 3 % of the range (six id
// lines of psi_q on a machine with little cross saturation) read as one
// band: a note names them and how far apart they are.
std::vector<std::string> BandNotes(const Curves& c, const char* name) {
  const auto& fam = c.fam;
  const auto& ys = c.ys;
  const auto& group = c.group;
  std::vector<std::string> bands;
  // 3 % of the view.
  const auto near = plot::CoincidentGroups(ys, 0.03 * c.view);
  for (size_t k = 0; k < fam.size(); ++k) {
    std::vector<size_t> members, leaders;
    for (size_t m = 0; m < fam.size(); ++m) {
      if (near[m] == k) members.push_back(m);
      if (near[m] == k && group[m] == m) leaders.push_back(m);
    }
    if (leaders.size() < 2) continue;
    double spread = 0;
    for (size_t i = 0; i < c.xs.size(); ++i) {
      double lo = 1e300, hi = -1e300;
      for (size_t m : members) lo = std::min(lo, ys[m][i]), hi = std::max(hi, ys[m][i]);
      spread = std::max(spread, hi - lo);
    }
    std::vector<double> t;
    for (size_t m : members) t.push_back(fam[m]);
    bands.push_back(absl::StrFormat("%s = %s lie within %s %s of each other", name, CurrentsText(c.over_id, t),
                                    Num(spread, Rounding{2, 0}), c.unit));
  }
  return bands;
}

// One line per group of coincident curves; returns a bit per source drawn.
unsigned DrawCurves(plot::Figure* f, const Curves& c, const Colours& colour_of, const char* name) {
  unsigned drawn = 0;
  for (size_t k = 0; k < c.fam.size(); ++k) {
    if (c.group[k] != k) continue;
    std::vector<double> members;
    for (size_t m = 0; m < c.fam.size(); ++m) {
      if (c.group[m] == k) members.push_back(c.fam[m]);
    }
    const bool pair = members.size() == 2 && members[0] == -members[1];
    const std::string label = absl::StrFormat("%s = %s%s", name, CurrentsText(c.over_id, members),
                                              members.size() > 1 && !pair ? " (coincide)" : "");
    plot::Style st;
    st.colour = colour_of(k);
    drawn |= LineBySource(f, c.xs, c.ys[k], c.src[k], st, label);
  }
  return drawn;
}

// The measured points by the curve group of their current, scaled like
// the curves: identified inductances (with their sigma) and, each kind
// with its own marker, steady-state rows' and flux map nodes' flux.
struct Points {
  std::vector<std::vector<double>> px, py, pe;
  std::vector<double> ssx, ssy, mx, my;
  std::vector<size_t> ssg, mg;
  size_t n_ind = 0, n_ss = 0, n_map = 0;
};

Points CollectPoints(const fit::Calibration& cal, const fit::FitData* data, Quantity q, const Curves& c,
                     double q_abs) {
  const bool over_id = c.over_id;
  const auto& fam = c.fam;
  const auto& group = c.group;
  const double scale = c.scale;
  const double fam_range = over_id ? 2 * q_abs : cal.id_max_a() - cal.id_min_a();
  Points p;
  p.px.resize(fam.size()), p.py.resize(fam.size()), p.pe.resize(fam.size());
  auto add = [&](double id, double iq, double x, double y, double e, double tol) {
    const int k = Member(fam, over_id ? iq : id, std::max(fam_range, 1.0), tol);
    if (k < 0) return false;
    const size_t g = group[k];
    p.px[g].push_back(x);
    p.py[g].push_back(scale * y);
    p.pe[g].push_back(scale * e);
    return true;
  };
  if (data == nullptr) return p;
  if (q == Quantity::kLdd || q == Quantity::kLqq || q == Quantity::kLdq) {
    for (const auto& o : data->inductances) {
      double v = 0, e = 0;
      if (q == Quantity::kLdd) v = o.ldd_h, e = o.ldd_h_std;
      if (q == Quantity::kLqq) v = o.lqq_h, e = o.lqq_h_std;
      if (q == Quantity::kLdq) {
        if (!o.ldq_h) continue;
        v = *o.ldq_h, e = o.ldq_h_std;
      }
      p.n_ind += add(o.id_a, o.iq_a, o.iq_a, v, e, 0);
    }
    return p;
  }
  const bool d = q == Quantity::kPsiD;
  for (const auto& s : data->steady_state) {
    double pd = 0, pq = 0;
    fit::SteadyStateFlux(s, cal.pole_pairs(), data->rs_ohm ? data->rs_ohm : cal.rs_ohm(), data->f_pwm_hz, &pd, &pq);
    const int k = Member(fam, over_id ? s.iq_a : s.id_a, std::max(fam_range, 1.0));
    if (k < 0 || !std::isfinite(pd) || !std::isfinite(pq)) continue;
    p.ssx.push_back(over_id ? s.id_a : s.iq_a);
    p.ssy.push_back(scale * (d ? pd : pq));
    p.ssg.push_back(group[k]);
    ++p.n_ss;
  }
  // Map nodes lie on a grid: a node belongs to a curve only at its
  // exact current (1 % of the range), not to the nearest one.
  for (const auto& n : data->fluxes) {
    const int k = Member(fam, over_id ? n.iq_a : n.id_a, std::max(fam_range, 1.0), 0.01 * std::max(fam_range, 1.0));
    if (k < 0) continue;
    p.mx.push_back(over_id ? n.id_a : n.iq_a);
    p.my.push_back(scale * (d ? n.psi_d_wb : n.psi_q_wb));
    p.mg.push_back(group[k]);
    ++p.n_map;
  }
  return p;
}

// Draws the measured points, sets the view from the measured surface and
// the points, and adds the points' legend entries. Returns whether the
// view cuts an extrapolated stretch.
bool DrawPointsAndView(plot::Figure* f, const Curves& c, const Points& p, const Colours& colour_of) {
  double m_lo = c.m_lo, m_hi = c.m_hi;
  for (size_t k = 0; k < c.fam.size(); ++k) {
    plot::Style st;
    st.colour = colour_of(k);
    if (!p.px[k].empty()) f->Scatter(p.px[k], p.py[k], st, "", p.pe[k]);
    for (size_t i = 0; i < p.py[k].size(); ++i) {
      m_lo = std::min(m_lo, p.py[k][i] - p.pe[k][i]), m_hi = std::max(m_hi, p.py[k][i] + p.pe[k][i]);
    }
  }
  for (const auto* v : {&p.ssy, &p.my}) {
    for (double y : *v) m_lo = std::min(m_lo, y), m_hi = std::max(m_hi, y);
  }
  // The view is the measured surface's (and the points'), with as much
  // room again as its span on either side: an extrapolation that runs away
  // (a spline's continuation) leaves the frame instead of flattening what
  // was measured.
  bool clipped = false;
  if (m_lo <= m_hi) {
    const double span = std::max(m_hi - m_lo, 1e-9 * std::max(1.0, std::abs(m_hi)));
    const double lo = std::max(c.y_lo, m_lo - span), hi = std::min(c.y_hi, m_hi + span);
    clipped = lo > c.y_lo || hi < c.y_hi;
    f->SetYRange(lo, hi);
  }
  auto scatter_kind = [&](const std::vector<double>& x, const std::vector<double>& y, const std::vector<size_t>& g,
                          double size_px) {
    for (size_t k = 0; k < c.fam.size(); ++k) {
      std::vector<double> a, b;
      for (size_t i = 0; i < x.size(); ++i) {
        if (g[i] == k) a.push_back(x[i]), b.push_back(y[i]);
      }
      if (a.empty()) continue;
      plot::Style st;
      st.colour = colour_of(k);
      st.marker_px = size_px;
      f->Scatter(a, b, st, "");
    }
  };
  scatter_kind(p.mx, p.my, p.mg, 2.2);
  scatter_kind(p.ssx, p.ssy, p.ssg, 4.2);
  plot::Style grey;
  grey.colour = "#555";
  if (p.n_ind > 0) f->Scatter({}, {}, grey, "identified, ±1 sigma");
  if (p.n_ss > 0) {
    grey.marker_px = 4.2;
    f->Scatter({}, {}, grey, "steady-state rows");
  }
  if (p.n_map > 0) {
    grey.marker_px = 2.2;
    f->Scatter({}, {}, grey, "flux map nodes");
  }
  return clipped;
}

void QuantityFigure(Page* page, const fit::Calibration& cal, const fit::FitData* data, const Coverage& cov,
                    Quantity q) {
  const bool over_id = q == Quantity::kPsiD;   // x axis id, curves per iq
  const std::vector<double> fam = Family(cal, data, over_id, cov);
  const double q_abs = std::max({std::abs(cov.iq_lo), std::abs(cov.iq_hi), cal.iq_max_a()});
  const double x_lo = over_id ? cal.id_min_a() : -q_abs;
  const double x_hi = over_id ? cal.id_max_a() : q_abs;
  const auto xs = Linspace(x_lo, x_hi, 121);
  const Spec& sp = SpecOf(q);
  plot::Figure f(std::string("fig-") + sp.id, 640, 440);
  f.SetLegendBelow(true);
  f.SetTitle(sp.title);
  f.SetXLabel(over_id ? "id [A]" : "iq [A]");
  f.SetXRange(x_lo, x_hi);
  // The frame ends where the surface's region ends (e.g. id 0.16 A): a
  // whole-tick end would leave a band with nothing in it.
  f.SetTight(true, false);
  const Curves c = SampleCurves(cal, cov, q, fam, xs);
  f.SetYLabel(absl::StrFormat("%s [%s]", sp.symbol, c.unit));
  const Colours colour_of(fam, over_id);
  const char* name = over_id ? "iq" : "id";
  const std::vector<std::string> bands = BandNotes(c, name);
  const unsigned drawn = DrawCurves(&f, c, colour_of, name);
  const Points p = CollectPoints(cal, data, q, c, q_abs);
  const bool clipped = DrawPointsAndView(&f, c, p, colour_of);
  SourceKey(&f, drawn, cov);
  if (clipped) f.Note("extrapolated stretches beyond the view are cut at the frame");
  for (const auto& band : bands) f.Note(band);
  std::vector<std::string> dots;
  if (p.n_ind > 0) dots.push_back(absl::StrFormat("%zu identified inductances (±1 sigma)", p.n_ind));
  if (p.n_ss > 0) {
    dots.push_back(absl::StrFormat("%zu steady-state rows' flux (psi_d = (uq - Rs iq) / w, psi_q = -(ud - Rs id) / w, "
                                   "delay-corrected: fit::SteadyStateFlux)", p.n_ss));
  }
  if (p.n_map > 0) dots.push_back(absl::StrFormat("%zu flux map nodes", p.n_map));
  page->Figure(f, absl::StrCat(
                      H(sp.title), " of ", H(cal.serial()), " from the fitted surface, one line per ", name,
                      " (curves within a pixel of each other drawn once, their entry names all)",
                      dots.empty() ? std::string(".")
                                   : absl::StrCat("; dots: ", H(absl::StrJoin(dots, ", ")),
                                                  ", in the colour of their ", name, "'s line."),
                      (drawn & 6u) ? absl::StrCat(" ", H(cov.OtherHalf()), ".") : std::string()));
}

}  // namespace

void SurfacesSection(const PageContext& ctx, Page* page) {
  std::string& b = page->body;
  b += "<section><h2>Inductances and flux linkages</h2><div class=\"grid\">\n";
  for (Quantity q : {Quantity::kLdd, Quantity::kLqq, Quantity::kLdq, Quantity::kPsiD, Quantity::kPsiQ}) {
    QuantityFigure(page, *ctx.cal, ctx.in->identified, ctx.cov, q);
  }
  b += "</div></section>\n";
}

}  // namespace fluxcal::report::internal
