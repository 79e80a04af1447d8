#include "fitting/large_signal.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <memory>
#include <vector>

#include "fitting/inductance_residual.h"
#include "fitting/problem.h"
#include "physics/hf_orbit.h"

namespace fluxcal::fit::internal {

namespace {

// The calibration as physics/hf_orbit.h's map: flux and (Ldd, Lqq, Ldq).
void MapAt(const Calibration& cal, double id, double iq, double* psi, double* l) {
  sim::FluxLinkage f;
  sim::DifferentialInductance L;
  cal.FluxAndInductance(id, iq, 25.0, &f, &L);
  psi[0] = f.psi_d_wb;
  psi[1] = f.psi_q_wb;
  l[0] = L.ldd_h;
  l[1] = L.lqq_h;
  l[2] = L.ldq_h;
}

// sum_k W_k[c] . psi(i_k) on `cal`.
void Describing(const Calibration& cal, const HfOrbitWeights& w, double* large) {
  for (int c = 0; c < 3; ++c) large[c] = 0.0;
  for (size_t k = 0; k < w.currents_a.size(); ++k) {
    double psi[2], l[3];
    MapAt(cal, w.currents_a[k][0], w.currents_a[k][1], psi, l);
    for (int c = 0; c < 3; ++c) large[c] += w.weights[c][k][0] * psi[0] + w.weights[c][k][1] * psi[1];
  }
}

}  // namespace

sim::DifferentialInductance PredictedInductance(const Calibration& cal, const InductanceObservation& obs) {
  if (!obs.hf_orbit) return cal.Inductance(obs.id_a, obs.iq_a);
  double large[3];
  Describing(cal, *obs.hf_orbit, large);
  return {large[0], large[1], large[2]};
}

int AttachHfOrbits(const Calibration& first, double sigma_floor, FitData* d, double* median_sigmas) {
  auto map = [&](double id, double iq, double* psi, double* l) { MapAt(first, id, iq, psi, l); };
  // An orbit wider than the whole region the points span is no
  // small excursion about its point (a radius a station sent wrong, or an
  // injection far too strong for the machine): its describing function
  // would be the surface's extrapolation, and its Newton solves the most
  // expensive. Such a point keeps the small-signal model; the first-order
  // excursion rho / lambda_min(L) is judged before any orbit is solved.
  const double current_scale = std::max(DataCurrentScaleA(*d), 1.0);
  int attached = 0;
  std::vector<double> sigmas;   // per solved orbit, its largest change in sigmas
  for (auto& obs : d->inductances) {
    if (!obs.hf_flux_radius_wb || !(*obs.hf_flux_radius_wb > 0)) continue;
    obs.hf_orbit.reset();
    {
      const auto L = first.Inductance(obs.id_a, obs.iq_a);
      const double mean = 0.5 * (L.ldd_h + L.lqq_h), half = std::hypot(0.5 * (L.ldd_h - L.lqq_h), L.ldq_h);
      const double lambda_min = mean - half;
      if (!(lambda_min > 0) || *obs.hf_flux_radius_wb / lambda_min > current_scale) continue;
    }
    auto w = std::make_shared<HfOrbitWeights>();
    if (!physics::HfOrbit(map, obs.id_a, obs.iq_a, *obs.hf_flux_radius_wb, &w->currents_a) ||
        !physics::DescribingWeights(w->currents_a, &w->weights)) {
      continue;
    }
    // What the orbit changes on the first pass's surfaces, in sigmas.
    double large[3];
    Describing(first, *w, large);
    double psi[2], small[3];
    map(obs.id_a, obs.iq_a, psi, small);
    const double mean = 0.5 * (std::abs(obs.ldd_h) + std::abs(obs.lqq_h));
    const double sigma[3] = {std::max(obs.ldd_h_std, sigma_floor * std::abs(obs.ldd_h)),
                             std::max(obs.lqq_h_std, sigma_floor * std::abs(obs.lqq_h)),
                             std::max(obs.ldq_h_std, sigma_floor * mean)};
    if (!std::all_of(large, large + 3, [](double v) { return std::isfinite(v); })) continue;
    double change = 0;
    for (int c = 0; c < 3; ++c) change = std::max(change, std::abs(large[c] - small[c]) / sigma[c]);
    sigmas.push_back(change);
    if (!(change > kLargeSignalMaterialSigma)) continue;
    obs.hf_orbit = std::move(w);
    ++attached;
  }
  if (median_sigmas != nullptr) {
    *median_sigmas = 0;
    if (!sigmas.empty()) {
      std::nth_element(sigmas.begin(), sigmas.begin() + static_cast<long>(sigmas.size() / 2), sigmas.end());
      *median_sigmas = sigmas[sigmas.size() / 2];
    }
  }
  return attached;
}

}  // namespace fluxcal::fit::internal
