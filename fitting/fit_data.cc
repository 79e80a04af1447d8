// The fit's input adapters (fitting/fit.h): observations from
// identification results, a set's hf_results rows or a flux map's nodes,
// and the flux linkage a steady-state row's voltages measure.
#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>

#include "fitting/fit.h"
#include "identification/identify.h"
#include "io/flux_map.h"
#include "physics/delay.h"
#include "physics/hf_orbit.h"
#include "physics/speed.h"

namespace fluxcal::fit {

void SteadyStateFlux(const SteadyStateObservation& s, int pole_pairs, std::optional<double> rs, double f_pwm_hz,
                     double* psi_d, double* psi_q) {
  const double rs_ohm = rs.value_or(0.0);   // unknown: the drop Rs i neglected (fit.h)
  const double we = physics::RpmToElectricalRadS(s.speed_rpm, pole_pairs);
  // steady_state.csv holds the fundamental dq command of a delay-compensated
  // controller (inverse Park at theta + 1.5 w_e Ts); the zero-order hold
  // still scales the fundamental the machine sees by sin(x)/x, x = w_e Ts/2
  // (identification/demod.h, eq. (V1)); 3e-4 at 2000 rpm, 4 pole pairs.
  const double g = physics::ZohGain(we, 1.0 / f_pwm_hz);
  const std::complex<double> u = std::complex<double>(s.ud_ref_v, s.uq_ref_v) * g;
  *psi_d = (u.imag() - rs_ohm * s.iq_a) / we;
  *psi_q = -(u.real() - rs_ohm * s.id_a) / we;
}

std::optional<double> HfFluxRadiusOf(const io::Manifest& manifest, const ident::HfPointResult& identified) {
  // physics/hf_orbit.h: a rotating injection's effective voltage |V| at w_i.
  const auto& inj = manifest.injection;
  if (!inj || inj->type != "rotating" || !(inj->frequency_hz > 0) || !(std::abs(identified.v_eff_v) > 0)) {
    return std::nullopt;
  }
  return physics::HfFluxRadiusWb(std::abs(identified.v_eff_v), 2 * std::numbers::pi * inj->frequency_hz);
}

FitData FitDataFromRecording(const io::RecordingSet& set,
                             const std::vector<ident::HfPointResult>& identified) {
  FitData d = FitDataFromHfRows(&set.manifest, set.hf_results);
  // The point's recorded temperature from the manifest (identification
  // reports 25 degC for a point that recorded none).
  auto point_temperature = [&](const std::string& id) -> std::optional<double> {
    for (const auto& p : set.manifest.points) {
      if (p.id == id) return p.temperature_c;
    }
    return std::nullopt;
  };
  for (const auto& r : identified) {
    if (!r.reliable && r.flags.size() == 1 && r.flags[0] == "clipping") continue;
    if (!std::isfinite(r.ld_h) || !std::isfinite(r.lq_h) || !std::isfinite(r.id_a)) continue;
    InductanceObservation o;
    o.id_a = r.id_a; o.iq_a = r.iq_a;
    o.ldd_h = r.ld_h; o.lqq_h = r.lq_h;
    o.ldd_h_std = r.ld_h_std; o.lqq_h_std = r.lq_h_std;
    if (r.has_ldq) { o.ldq_h = r.ldq_h; o.ldq_h_std = r.ldq_h_std; }
    // The bench's own hf_results rows say nothing of how they were
    // measured: small-signal.
    o.hf_flux_radius_wb = HfFluxRadiusOf(set.manifest, r);
    o.temperature_c = point_temperature(r.point);
    d.inductances.push_back(o);
  }
  for (const auto& s : set.steady_state) {
    SteadyStateObservation o{s.id_a, s.iq_a, s.speed_rpm, s.ud_ref_v, s.uq_ref_v, s.torque_nm};
    o.current_ripple_a = s.current_ripple_a;
    o.voltage_limited_share = s.voltage_limited_share;
    o.controller_saturated_share = s.controller_saturated_share;
    o.temperature_c = s.temperature_c;
    d.steady_state.push_back(o);
  }
  return d;
}

FitData FitDataFromHfRows(const io::Manifest* m, const std::vector<io::HfResultRow>& rows) {
  FitData d;
  if (m) {
    d.serial = m->serial;
    d.pole_pairs = m->motor.pole_pairs;
    d.rs_ohm = m->motor.rs_ohm;
    d.f_pwm_hz = m->drive.f_pwm_hz.value_or(m->drive.f_sample_hz);
    d.psi_pm_prior_wb = m->motor.psi_pm_wb;
    d.udc_v = m->drive.udc_v;
    d.psi_pm_temp_coeff_per_k = m->motor.psi_pm_temp_coeff_per_k;
  }
  for (const auto& r : rows) {
    InductanceObservation o;
    o.id_a = r.id_a; o.iq_a = r.iq_a; o.ldd_h = r.ld_h; o.lqq_h = r.lq_h; o.ldq_h = r.ldq_h;
    o.temperature_c = r.temperature_c;
    d.inductances.push_back(o);
  }
  return d;
}

FitData FitDataFromFluxMap(const io::FluxMap& map, int pole_pairs, double psi_std_wb) {
  FitData d;
  d.pole_pairs = pole_pairs;
  const auto points = map.Points();
  if (!(psi_std_wb > 0)) {
    double scale = 0;
    for (const auto& p : points) scale = std::max(scale, std::hypot(p.psi_d_wb, p.psi_q_wb));
    psi_std_wb = 0.002 * scale;
  }
  for (const auto& p : points) {
    d.fluxes.push_back({p.id_a, p.iq_a, p.psi_d_wb, p.psi_q_wb, psi_std_wb});
    // The prior's sigma is relative to it: only a magnet flux (> 0) is one
    // (a synchronous reluctance map has psi_d(0, 0) = 0).
    if (p.id_a == 0 && p.iq_a == 0 && p.psi_d_wb > 0) d.psi_pm_prior_wb = p.psi_d_wb;
  }
  return d;
}

std::optional<MagnetReference> MagnetReferenceOf(const FitData& used) {
  double lo = 0, hi = 0, sum = 0;
  size_t n = 0;
  auto add = [&](const std::optional<double>& t) {
    if (!t || !std::isfinite(*t)) return false;
    lo = n == 0 ? *t : std::min(lo, *t);
    hi = n == 0 ? *t : std::max(hi, *t);
    sum += *t;
    ++n;
    return true;
  };
  for (const auto& o : used.inductances) {
    if (!add(o.temperature_c)) return std::nullopt;
  }
  for (const auto& o : used.steady_state) {
    if (!add(o.temperature_c)) return std::nullopt;
  }
  for (const auto& o : used.fluxes) {
    if (!add(o.temperature_c)) return std::nullopt;
  }
  if (n == 0) return std::nullopt;
  return MagnetReference{sum / static_cast<double>(n), hi - lo};
}

}  // namespace fluxcal::fit
