// The waveform locator's second half (docs/diagnosis.md, "The
// waveforms"): the lines AnalyseWaveforms (waveform.cc) found at each point,
// grouped by what they are multiples of across points, judged against the
// number of places they could have been, and reported as mismatches with
// their size, significance and trend.
#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <tuple>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "diagnosis/internal.h"

namespace fluxcal::diag::detail {
namespace {

// Look-elsewhere: a line found by scanning ~1000 bins at each of ~40
// points is judged against the number of places it could have been; a
// named family against the number of names (rotor-frame harmonics x
// sidebands, electrical harmonics, mechanical orders). For large z the
// Gaussian tail gives z_adjusted^2 ~ z^2 - 2 ln N.
constexpr double kNamedFamilies = 300.0;
double LookElsewhere(double z, double trials) {
  if (z <= 0 || trials <= 1) return z;
  return std::sqrt(std::max(0.0, z * z - 2.0 * std::log(trials)));
}

// Gaussian-equivalent significance of a chi^2 with nu degrees of freedom
// (Wilson-Hilferty cube-root transform).
double ChiSquareSigma(double chi2, double nu) {
  if (nu <= 0) return 0.0;
  const double a = 2.0 / (9.0 * nu);
  return (std::cbrt(chi2 / nu) - (1.0 - a)) / std::sqrt(a);
}
std::string KindText(const std::string& kind, int order, int m, double f_hz) {
  if (kind == "electrical_harmonic") return absl::StrFormat("at speed, harmonic %d of the electrical frequency", order);
  if (kind == "mechanical_order") {
    return absl::StrFormat("at speed, mechanical order %d (%d x the electrical frequency / pole pairs)", order, order);
  }
  if (kind == "injection_sideband") {
    return absl::StrFormat("at speed, sideband %+d x f_e of the HF response's rotor-frame harmonic %d", order, m);
  }
  if (kind == "injection_harmonic") return absl::StrFormat("harmonic %d of the injection", order);
  if (kind == "fixed_frequency_line") return absl::StrFormat("a line at %.0f Hz at every speed", f_hz);
  return absl::StrFormat("a line at %.0f Hz that no multiple of the electrical, mechanical or injection "
                         "frequency explains",
                         f_hz);
}

double Correlation(const std::vector<double>& x, const std::vector<double>& y) {
  const size_t n = x.size();
  if (n < 3) return 0.0;
  const double mx = std::accumulate(x.begin(), x.end(), 0.0) / n, my = std::accumulate(y.begin(), y.end(), 0.0) / n;
  double sxy = 0, sxx = 0, syy = 0;
  for (size_t i = 0; i < n; ++i) {
    sxy += (x[i] - mx) * (y[i] - my);
    sxx += (x[i] - mx) * (x[i] - mx);
    syy += (y[i] - my) * (y[i] - my);
  }
  return sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : 0.0;
}

}  // namespace

std::vector<Mismatch> WaveformMismatches(const std::vector<WaveformPoint>& pts, int pole_pairs, double f_inj_hz,
                                         double sigma_threshold) {
  // Group the lines: named ones by (channel, kind, order, m); the others by
  // frequency (a line at one frequency at several points is interference,
  // not the machine).
  struct Group {
    std::string channel, kind;
    int order = 0, m = 0;
    double freq_hz = 0;
    std::vector<std::pair<double, std::string>> seen;   // (z2, point)
    double size_a = 0, sigma = 0;
    std::string dependence;
  };
  std::map<std::tuple<std::string, std::string, int, int, long>, Group> groups;
  size_t bins = 0;
  for (const auto& wp : pts) {
    bins += wp.spectrum.size();
    for (const auto& l : wp.lines) {
      const bool named = !l.kind.empty();
      const long fkey = named ? 0 : std::lround(l.freq_hz / std::max(wp.df_hz, 1e-9));
      auto& g = groups[{l.channel, named ? l.kind : "line", l.order, l.m, fkey}];
      g.channel = l.channel;
      g.kind = named ? l.kind : "line";
      g.order = l.order;
      g.m = l.m;
      g.freq_hz = l.freq_hz;
      g.seen.push_back({l.z2, wp.point});
      g.size_a = std::max(g.size_a, l.amp_a);
    }
  }
  std::vector<Group> located;
  for (auto& [key, g] : groups) {
    (void)key;
    // The group's line measured at every point of its regime (turning or
    // not), seen or not: its power there, for the significance over all of
    // them, and its size for the dependence on order, current and speed.
    std::vector<double> z2s, amps, order_idx, current, speed;
    for (const auto& wp : pts) {
      if (g.channel == "phase_voltage") {
        // Tested by regression where the record allows it
        // (mechanical_orders.cc): the lines' own z^2, no spectrum.
        for (const auto& l : wp.lines) {
          if (l.channel != g.channel || l.kind != g.kind || l.order != g.order) continue;
          z2s.push_back(l.z2);
          amps.push_back(l.amp_a);
          order_idx.push_back(static_cast<double>(wp.index));
          current.push_back(std::hypot(wp.id_a, wp.iq_a));
          speed.push_back(std::abs(wp.speed_rpm));
        }
        continue;
      }
      const bool turning = std::abs(wp.f_e_hz) >= 3 * wp.df_hz;
      double f = g.freq_hz;
      if (g.kind == "electrical_harmonic") {
        if (!turning) continue;
        f = g.order * wp.f_e_hz;
      } else if (g.kind == "mechanical_order") {
        if (!turning) continue;
        f = g.order * wp.f_e_hz / pole_pairs;
      } else if (g.kind == "injection_sideband") {
        if (!turning) continue;
        f = wp.f_e_hz + g.m * (f_inj_hz - wp.f_e_hz) + g.order * wp.f_e_hz;
      } else if (g.kind == "injection_harmonic") {
        f = turning ? wp.f_e_hz + g.m * (f_inj_hz - wp.f_e_hz) : g.m * f_inj_hz;
      }
      const bool zero = g.channel != "phase_current";   // a real signal's channel
      if (zero) f = std::abs(f);
      const auto& spec = g.channel == "zero_sequence_current" ? wp.spectrum_zero
                         : g.channel == "rotor_angle"        ? wp.spectrum_angle
                                                             : wp.spectrum;
      const double s2 = g.channel == "zero_sequence_current" ? wp.sigma2_bin_zero
                        : g.channel == "rotor_angle"        ? wp.sigma2_bin_angle
                                                            : wp.sigma2_bin;
      if (spec.empty()) continue;
      bool nuisance = false;   // a nuisance bin carries no test
      for (double nf : wp.nuisance_hz) nuisance |= std::abs(f - nf) <= 2.5 * wp.df_hz;
      if (g.channel == "rotor_angle") {
        for (double nf : wp.angle_nuisance_hz) nuisance |= std::abs(std::abs(f) - std::abs(nf)) <= 2.5 * wp.df_hz;
      }
      if (nuisance) continue;
      const long nb = static_cast<long>(spec.size());
      const long b0 = std::lround(f / wp.df_hz);
      // The largest of the bin and its neighbours (the line between bins).
      double best = 0, best_amp = 0;
      for (long d = -1; d <= 1; ++d) {
        const long b = ((b0 + d) % nb + nb) % nb;
        const double model = g.channel == "phase_current" ? ModelLineSize(wp.spectrum_sim, static_cast<size_t>(b))
                             : g.channel == "rotor_angle" && !wp.spectrum_angle_model.empty()
                                 ? kModelLineAccuracy * std::abs(wp.spectrum_angle_model[b])
                                 : 0.0;
        const double z2 = std::norm(spec[b]) / (s2 + model * model + QuantisationPower(wp, g.channel, b));
        if (z2 > best) { best = z2; best_amp = std::abs(spec[b]); }
      }
      z2s.push_back(best);
      amps.push_back(best_amp / wp.coherent_gain * (zero ? 2.0 : 1.0));
      order_idx.push_back(static_cast<double>(wp.index));
      current.push_back(std::hypot(wp.id_a, wp.iq_a));
      speed.push_back(std::abs(wp.speed_rpm));
    }
    // Significance: the sum of z^2 over the points it was looked for at
    // (each ~ chi^2_2 / 2 under noise; the best of three bins counted as
    // one less ln 3), or the single strongest line, whichever says more,
    // each against the number of places such a line could have been found.
    double chi2 = 0;
    for (double z : z2s) chi2 += 2.0 * std::max(0.0, z - std::log(3.0));
    double strongest = 0;
    for (const auto& seen : g.seen) strongest = std::max(strongest, seen.first);
    const bool named = g.kind != "line";
    const double trials = named ? kNamedFamilies : static_cast<double>(std::max<size_t>(bins, 1));
    g.sigma = std::max(LookElsewhere(ChiSquareSigma(chi2, 2.0 * std::max<size_t>(1, z2s.size())), trials),
                       LookElsewhere(ChiSquareSigma(2.0 * strongest, 2.0), trials));
    if (g.sigma < sigma_threshold) continue;
    if (g.kind == "line") g.kind = g.seen.size() >= 2 ? "fixed_frequency_line" : "unexplained_line";
    std::vector<std::string> dep;
    if (amps.size() >= 4) {
      const double ro = Correlation(order_idx, amps), rc = Correlation(current, amps), rs = Correlation(speed, amps);
      if (std::abs(ro) >= 0.7) dep.push_back(absl::StrFormat("%s over the recording order (r = %.2f)", ro > 0 ? "grows" : "falls", ro));
      if (std::abs(rc) >= 0.7) dep.push_back(absl::StrFormat("%s with the current magnitude (r = %.2f)", rc > 0 ? "grows" : "falls", rc));
      if (std::abs(rs) >= 0.7) dep.push_back(absl::StrFormat("%s with speed (r = %.2f)", rs > 0 ? "grows" : "falls", rs));
    }
    g.dependence = absl::StrJoin(dep, "; ");
    located.push_back(g);
  }
  // One mismatch per kind of component and channel: its strongest member
  // gives order, frequency and dependence; the others are listed.
  std::map<std::pair<std::string, std::string>, std::vector<const Group*>> by_kind;
  for (const auto& g : located) by_kind[{g.channel, g.kind}].push_back(&g);
  std::vector<Mismatch> out;
  for (auto& [key, members] : by_kind) {
    std::sort(members.begin(), members.end(), [](const Group* a, const Group* b) { return a->sigma > b->sigma; });
    const Group& top = *members.front();
    Mismatch mm;
    mm.signal = key.first;
    mm.kind = key.second;
    mm.order = top.order;
    mm.frequency_hz = (mm.kind == "fixed_frequency_line" || mm.kind == "unexplained_line" ||
                       (mm.kind == "injection_harmonic" && std::abs(top.freq_hz) > 0))
                          ? top.freq_hz
                          : 0.0;
    mm.significance_sigma = top.sigma;
    mm.dependence = top.dependence;
    std::vector<std::string> others;
    std::map<std::string, double> points;
    for (const Group* g : members) {
      mm.size_a = std::max(mm.size_a, g->size_a);
      if (g != &top && others.size() < 8) {
        others.push_back(g->kind == "fixed_frequency_line" || g->kind == "unexplained_line"
                             ? absl::StrFormat("%.0f Hz", g->freq_hz)
                             : (g->kind == "injection_sideband" ? absl::StrFormat("%+d (beside %d)", g->order, g->m)
                                                                 : absl::StrFormat("%d", g->order)));
      }
      for (const auto& seen : g->seen) points[seen.second] = std::max(points[seen.second], seen.first);
    }
    mm.where = KindText(mm.kind, top.order, top.m, top.freq_hz) +
               (mm.signal == "zero_sequence_current" ? ", in the zero sequence (ia + ib + ic)"
                : mm.signal == "rotor_angle"         ? ", in the recorded rotor angle beyond its constant speed (rad)"
                : mm.signal == "phase_voltage"
                    ? ", in the voltage the bench's current controller commanded (rotor frame, V): the controller "
                      "held the current against it"
                    : ", in the phase currents");
    if (!others.empty()) {
      mm.where += absl::StrFormat("; %zu more of its kind%s (%s%s)", members.size() - 1,
                                  members.size() - 1 > others.size() ? ", strongest" : "", absl::StrJoin(others, ", "),
                                  members.size() - 1 > others.size() ? ", ..." : "");
    }
    std::vector<std::pair<double, std::string>> ranked;
    for (const auto& [pt, z] : points) ranked.push_back({z, pt});
    std::sort(ranked.rbegin(), ranked.rend());
    for (const auto& r : ranked) {
      if (mm.points.size() < 12) mm.points.push_back(r.second);
    }
    out.push_back(std::move(mm));
  }
  std::sort(out.begin(), out.end(),
            [](const Mismatch& a, const Mismatch& b) { return a.significance_sigma > b.significance_sigma; });
  return out;
}

}  // namespace fluxcal::diag::detail
