#include <algorithm>
#include <cmath>

#include "diagnosis/effects/effect_term.h"
#include "diagnosis/internal.h"

namespace fluxcal::diag::detail {

// The three phase gains of m1, m2 (g_x = m1 + 2 Re(m2 e^{-j 2 phi_x}), sum of
// the deviations zero) and the zero-sum phase offsets of an alpha-beta
// offset o (o_x = Re(o e^{-j phi_x})).
extern const double kPhasePhi[3];
const double kPhasePhi[3] = {0, 2 * kPi / 3, 4 * kPi / 3};
double PhaseGain(double m1, Complex m2, int x) { return m1 + 2 * std::real(m2 * std::polar(1.0, -2 * kPhasePhi[x])); }
double PhaseOffset(Complex o, int x) { return std::real(o * std::polar(1.0, -kPhasePhi[x])); }

// The finding for an accepted candidate: the catalogue's explanation and
// the block's parameters in the catalogue's names and units (each effect's
// describe, diagnosis/effects/).
Finding Describe(const Candidate& c, const Model& m, const FitOut& f) {
  Finding out;
  out.effect = c.effect;
  const sim::EffectRow* row = sim::FindEffect(c.effect);
  if (row != nullptr) out.explanation = std::string(row->explanation);
  const EffectTerm* term = FindTerm(c.effect);
  if (term != nullptr && term->describe != nullptr) {
    const auto ptr = f.p.Ptrs();
    term->describe(c, m, f, ptr.data(), &out);
  }
  return out;
}

// Whether every parameter of a candidate's fit lies within its plausible
// range (catalogue's plausible_min .. plausible_max) or within 3
// standard deviations of it.
bool Plausible(const Candidate& c, const FitOut& f, const Model& m) {
  const Finding d = Describe(c, m, f);
  const sim::EffectRow* row = sim::FindEffect(c.effect);
  if (row == nullptr) return true;
  for (const auto& par : row->parameters) {
    const auto it = d.parameters.find(std::string(par.name));
    if (it == d.parameters.end()) continue;
    const auto sd = d.parameter_std.find(std::string(par.name));
    const double s = sd == d.parameter_std.end() ? 0.0 : sd->second;
    if (it->second < par.plausible_min - 3 * s || it->second > par.plausible_max + 3 * s) return false;
  }
  return true;
}

// A catalogue parameter's materiality floor on this set, in the
// parameter's unit: a floor stated against a scale of the machine means the
// same on every machine (sim::FloorScale); a relative one is a fraction of
// the manifest's nominal value.
// The manifest's nominal value a kRelativeNominal parameter is judged
// against (Rs or psi_pm).
double NominalOf(const sim::EffectParameter& par, const Model& m) {
  return par.name == "rs_ohm" ? m.rs_nom : m.psi_nom;
}

double FloorValue(const sim::EffectParameter& par, const Model& m) {
  if (par.floor_kind == sim::FloorKind::kRelativeNominal) {
    return par.floor * std::max(std::abs(NominalOf(par, m)), par.name == "rs_ohm" ? 1e-3 : 0.0);
  }
  return par.floor * m.FloorScaleValue(par.floor_scale);
}

// Distance of an effect's parameter from neutral, in standard deviations.
double Significance(const Candidate& c, const FitOut& f, const Model& m) {
  // Materiality (the catalogue's floors): below them no calibration
  // decision changes, however precisely the data pin the value down. The
  // size of a finding is its largest parameter's distance from neutral.
  const Finding d = Describe(c, m, f);
  const sim::EffectRow* row = sim::FindEffect(c.effect);
  if (row == nullptr) return 0.0;
  bool material = false;
  for (const auto& par : row->parameters) {
    const auto it = d.parameters.find(std::string(par.name));
    if (it == d.parameters.end() || par.name == "order") continue;
    double size = 0;
    const double floor = FloorValue(par, m);
    if (par.floor_kind == sim::FloorKind::kBelow) {
      // A parallel resistance: material when present (> 0) and small.
      if (it->second > 0 && it->second <= floor) material = true;
      continue;
    }
    if (par.floor_kind == sim::FloorKind::kRelativeNominal) {
      size = std::abs(it->second - NominalOf(par, m));
    } else {
      // The reported dead time includes what the manifest declares
      // uncompensated (part of the nominal model); the finding is the rest.
      const double reference = par.name == "dead_time_s" ? m.dead_nom_s : par.neutral;
      size = std::abs(it->second - reference);
    }
    if (size >= floor) material = true;
  }
  if (!material) return 0.0;
  if (!f.stdev.count(c.block)) return 0.0;
  if (!Plausible(c, f, m)) return 0.0;
  double best = 0;
  for (int i = 0; i < kBlockSize[c.block]; ++i) {
    const double sd = f.stdev.at(c.block)[i];
    if (sd > 0) best = std::max(best, std::abs(f.p.b[c.block][i]) / sd);
  }
  return best;
}

// Hausman's statistic of a held-out fit (docs/diagnosis.md, "Held-out HF
// phasors"): the largest move of an effect parameter of `free` from the
// full fit's, in standard deviations of the difference.
double ParameterShiftSigma(const FitOut& held, const FitOut& full, const std::vector<Block>& free) {
  double worst = 0;
  for (Block b : free) {
    if (b == kBase || !held.stdev.count(b) || !full.stdev.count(b)) continue;
    for (int i = 0; i < kBlockSize[b]; ++i) {
      const double d = held.p.b[b][i] - full.p.b[b][i];
      if (d == 0.0) continue;
      const double sf = held.stdev.at(b)[i], sc = full.stdev.at(b)[i];
      // The difference's variance is sd_without^2 - sd_full^2 where
      // that is positive; where the two fits' chi^2 scales make it not
      // (the full fit's residual is worse than the noise model), the
      // sum, as if the estimates were independent (conservative). Where
      // the class hardly informs a parameter (sd_without ~ sd_full) the
      // difference is ill-conditioned: its sd is floored at 10 % of
      // sd_without, below which the two solves' own tolerances and the
      // covariances' accuracy make any move meaningless.
      const double var = sf > sc ? std::max(sf * sf - sc * sc, 0.01 * sf * sf) : sf * sf + sc * sc;
      if (var > 0) worst = std::max(worst, std::abs(d) / std::sqrt(var));
    }
  }
  return worst;
}

// Whether some finding's catalogue parameter moved between the fits by its
// materiality floor or more (the floor of Significance).
bool MaterialMove(const std::vector<Candidate>& findings, const Model& m, const FitOut& a, const FitOut& b) {
  for (const Candidate& c : findings) {
    const sim::EffectRow* row = sim::FindEffect(c.effect);
    if (row == nullptr) continue;
    const Finding fa = Describe(c, m, a), fb = Describe(c, m, b);
    for (const auto& par : row->parameters) {
      const auto ia = fa.parameters.find(std::string(par.name)), ib = fb.parameters.find(std::string(par.name));
      if (ia == fa.parameters.end() || ib == fb.parameters.end() || par.name == "order") continue;
      const double floor = FloorValue(par, m);
      if (par.floor_kind == sim::FloorKind::kBelow) {
        // A parallel resistance: its conductance moves by the floor's.
        auto g = [](double r) { return r > 0 ? 1.0 / r : 0.0; };
        if (floor > 0 && std::abs(g(ia->second) - g(ib->second)) >= 1.0 / floor) return true;
      } else if (std::abs(ia->second - ib->second) >= floor) {
        return true;
      }
    }
  }
  return false;
}

// Whether every effect block of `free` is found in the held-out fit too
// (some parameter parameter_sigma from neutral): the other classes
// witness it, so its value can be compared.
bool FoundWithout(const FitOut& held, const std::vector<Block>& free, double parameter_sigma) {
  for (Block b : free) {
    if (b == kBase) continue;
    if (!held.stdev.count(b)) return false;
    double best = 0;
    for (int i = 0; i < kBlockSize[b]; ++i) {
      const double sd = held.stdev.at(b)[i];
      if (sd > 0) best = std::max(best, std::abs(held.p.b[b][i]) / sd);
    }
    if (best < parameter_sigma) return false;
  }
  return true;
}

}  // namespace fluxcal::diag::detail
