// Where a value on the page comes from (measured, by symmetry,
// extrapolated): the measured region, the line patterns that say it, and
// where the fitted inductance is not positive definite.
#include <algorithm>
#include <cmath>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "plot/plot.h"
#include "report/format.h"
#include "report/internal.h"

namespace fluxcal::report::internal {

// Source and plot::Provenance number the same three classes.
const char* DashOf(Source s) { return plot::ProvenanceDash(static_cast<plot::Provenance>(s)); }

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

}  // namespace fluxcal::report::internal
