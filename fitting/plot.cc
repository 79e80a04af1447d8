#include "fitting/plot.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "plot/plot.h"

namespace fluxcal::fit {
namespace {

// Inductances are quoted in mH: the values engineers compare.
constexpr double kMilli = 1e3;

// Distinct values, merged when closer than `tol` (operating points are held
// to a reference with a little control error); each level is the mean of
// the values it merges, so that a label names what was held.
std::vector<double> Levels(std::vector<double> v, double tol) {
  std::sort(v.begin(), v.end());
  std::vector<double> out;
  std::vector<size_t> count;
  for (double x : v) {
    if (out.empty() || x - out.back() / count.back() > tol) {
      out.push_back(x);
      count.push_back(1);
    } else {
      out.back() += x;
      ++count.back();
    }
  }
  for (size_t k = 0; k < out.size(); ++k) out[k] /= count[k];
  return out;
}

size_t Nearest(const std::vector<double>& levels, double v) {
  size_t best = 0;
  for (size_t k = 1; k < levels.size(); ++k) {
    if (std::abs(levels[k] - v) < std::abs(levels[best] - v)) best = k;
  }
  return best;
}

// "iq = 40 A", "iq = 0, 40, 80 A" (curves that lie on top of each other,
// drawn once), "iq = 0 .. 160 A (6 levels, one curve)" when the list would
// be long.
std::string LevelLabel(const char* name, const std::vector<double>& values) {
  std::vector<std::string> v;
  for (double x : values) v.push_back(absl::StrFormat("%.0f", std::round(x) + 0.0));
  if (v.size() > 4) {
    return absl::StrFormat("%s = %s .. %s A (%zu levels, one curve)", name, v.front(), v.back(), v.size());
  }
  return absl::StrFormat("%s = %s A", name, absl::StrJoin(v, ", "));
}

// One panel: L (Ldd or Lqq) against x (id or iq), one curve per level of
// the other current, identified points in the colour of their curve.
struct PanelSpec {
  bool ldd;                 // Ldd over id (curves per iq), else Lqq over iq (curves per id)
  const char* id;
  const char* title;
  const char* xlabel;
  const char* ylabel;
  const char* level_name;   // the current held constant along a curve
};

plot::Figure Panel(const Calibration& cal, const FitData& data, const PanelSpec& p, double x_lo, double x_hi,
                   const std::vector<double>& levels) {
  plot::Figure f(p.id, 600, 500);
  f.SetTitle(p.title);
  // Below the axes: level lists are long, the curves need the width.
  f.SetLegendBelow(true);
  f.SetXLabel(p.xlabel);
  f.SetYLabel(p.ylabel);
  // The frame ends at the data's extent (plus a margin for the dots):
  // whole-tick ends would add bands with nothing in them.
  const double pad = 0.04 * std::max(1.0, x_hi - x_lo);
  f.SetXRange(x_lo - pad, x_hi + pad);
  f.SetTight(true, false);
  constexpr int kSamples = 81;
  std::vector<double> xs;
  for (int k = 0; k < kSamples; ++k) xs.push_back(x_lo - pad + (x_hi - x_lo + 2 * pad) * k / (kSamples - 1));
  std::vector<std::vector<double>> curves(levels.size());
  std::vector<std::vector<bool>> extrapolated(levels.size());
  double y_lo = std::numeric_limits<double>::infinity(), y_hi = -y_lo;
  for (size_t l = 0; l < levels.size(); ++l) {
    for (double x : xs) {
      const double id = p.ldd ? x : levels[l], iq = p.ldd ? levels[l] : x;
      const auto L = cal.Inductance(id, iq);
      const double v = kMilli * (p.ldd ? L.ldd_h : L.lqq_h);
      curves[l].push_back(v);
      extrapolated[l].push_back(!cal.InMeasuredRegion(id, iq));
      if (std::isfinite(v)) y_lo = std::min(y_lo, v), y_hi = std::max(y_hi, v);
    }
  }
  // Curves closer than 0.5 % of the panel's range (about a pixel) are one
  // line: drawn once, with one legend entry naming all their levels.
  const double tol = 0.005 * std::max(y_hi - y_lo, 1e-9);
  const auto group = plot::CoincidentGroups(curves, tol);
  std::vector<size_t> colour_of(levels.size());
  size_t colours = 0;
  bool any_extrapolated = false;
  for (size_t l = 0; l < levels.size(); ++l) {
    if (group[l] != l) {
      colour_of[l] = colour_of[group[l]];
      continue;
    }
    colour_of[l] = colours++;
    std::vector<double> members;
    for (size_t m = l; m < levels.size(); ++m) {
      if (group[m] == l) members.push_back(levels[m]);
    }
    plot::Style st;
    st.colour = plot::Palette(static_cast<int>(colour_of[l]));
    // The measured stretch solid, the extrapolated one dashed; each keeps
    // the sample where the state changes, so that the two join.
    std::vector<double> in(curves[l].size(), std::nan("")), out(curves[l].size(), std::nan(""));
    for (size_t k = 0; k < curves[l].size(); ++k) {
      const bool ex = extrapolated[l][k];
      const bool edge = (k > 0 && extrapolated[l][k - 1] != ex) ||
                        (k + 1 < curves[l].size() && extrapolated[l][k + 1] != ex);
      (ex ? out : in)[k] = curves[l][k];
      if (edge) in[k] = out[k] = curves[l][k];
      any_extrapolated |= ex;
    }
    f.Line(xs, in, st, LevelLabel(p.level_name, members));
    plot::Style dashed = st;
    dashed.dash = "5 3";
    f.Line(xs, out, dashed, "");
  }
  // Identified points with +-1 sigma, in the colour of their curve.
  std::vector<std::vector<double>> px(colours), py(colours), pe(colours);
  for (const auto& o : data.inductances) {
    const size_t c = colour_of[Nearest(levels, p.ldd ? std::abs(o.iq_a) : o.id_a)];
    px[c].push_back(p.ldd ? o.id_a : std::abs(o.iq_a));
    py[c].push_back(kMilli * (p.ldd ? o.ldd_h : o.lqq_h));
    pe[c].push_back(kMilli * (p.ldd ? o.ldd_h_std : o.lqq_h_std));
  }
  for (size_t c = 0; c < colours; ++c) {
    plot::Style st;
    st.colour = plot::Palette(static_cast<int>(c));
    st.marker_px = 3;
    f.Scatter(px[c], py[c], st, "", pe[c]);
  }
  plot::Style grey;
  grey.colour = "#555";
  grey.marker_px = 3;
  if (!data.inductances.empty()) f.Scatter({}, {}, grey, "identified, +-1 sigma");
  if (any_extrapolated) {
    grey.dash = "5 3";
    f.Line({}, {}, grey, "outside the measured region");
  }
  return f;
}

}  // namespace

std::string PlotFitSvg(const Calibration& cal, const FitData& data) {
  const auto& obs = data.inductances;
  double id_lo = 0, id_hi = 0, iq_hi = 1;
  bool negative_iq = false;
  std::vector<double> ids, iqs;
  for (const auto& o : obs) {
    id_lo = std::min(id_lo, o.id_a);
    id_hi = std::max(id_hi, o.id_a);
    iq_hi = std::max(iq_hi, std::abs(o.iq_a));
    negative_iq |= o.iq_a < 0;
    ids.push_back(o.id_a);
    iqs.push_back(std::abs(o.iq_a));
  }
  const double tol = 0.03 * std::max(std::max(1.0, id_hi - id_lo), iq_hi);
  std::vector<double> iq_levels = Levels(iqs, tol), id_levels = Levels(ids, tol);
  // Without data, one curve through the middle of the measured region.
  if (iq_levels.empty()) iq_levels = {0.5 * (cal.iq_min_a() + cal.iq_max_a())};
  if (id_levels.empty()) id_levels = {0.5 * (cal.id_min_a() + cal.id_max_a())};
  if (obs.empty()) {
    id_lo = cal.id_min_a();
    id_hi = cal.id_max_a();
    iq_hi = std::max(1.0, cal.iq_max_a());
  }
  const char* iq_axis = negative_iq ? "|iq| [A]" : "iq [A]";
  const std::vector<plot::Figure> panels = {
      Panel(cal, data,
            {true, "fit-ldd", "Ldd = dpsi_d/did against id", "id [A]", "Ldd [mH]", negative_iq ? "|iq|" : "iq"}, id_lo,
            id_hi, iq_levels),
      Panel(cal, data, {false, "fit-lqq", "Lqq = dpsi_q/diq against iq", iq_axis, "Lqq [mH]", "id"}, 0.0, iq_hi,
            id_levels)};
  return plot::PanelsSvg(
      "fit",
      absl::StrFormat("%s: fitted %s (lines: one per held current, dashed outside the measured region) against the "
                      "%zu identified inductances (dots, +-1 sigma)",
                      cal.serial(), cal.family().Name(), obs.size()),
      panels, 2);
}

}  // namespace fluxcal::fit
