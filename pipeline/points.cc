// The identified HF point converted to and from every shape, a recording
// set identified into points, and fit data from points or a set
// (pipeline/points.h).
#include "pipeline/pipeline.h"

#include <cmath>

#include "absl/strings/str_cat.h"
#include "pipeline/identify.h"

namespace fluxcal::pipeline {

bool FromIdentification(const ident::HfPointResult& r, IdentifiedPoint* h) {
  if (!std::isfinite(r.ld_h) || !std::isfinite(r.id_a)) return false;   // identification_failed
  *h = IdentifiedPoint{};
  h->point_id = r.point; h->id_a = r.id_a; h->iq_a = r.iq_a; h->speed_rpm = r.speed_rpm;
  h->ld_h = r.ld_h; h->lq_h = r.lq_h;
  if (r.has_ldq) h->ldq_h = r.ldq_h;
  h->ld_h_std = r.ld_h_std; h->lq_h_std = r.lq_h_std; h->ldq_h_std = r.ldq_h_std;
  h->temperature_c = r.temperature_c; h->reliable = r.reliable;
  return true;
}

fit::InductanceObservation ToObservation(const IdentifiedPoint& p) {
  fit::InductanceObservation o;
  o.id_a = p.id_a; o.iq_a = p.iq_a; o.ldd_h = p.ld_h; o.lqq_h = p.lq_h; o.ldq_h = p.ldq_h;
  o.ldd_h_std = p.ld_h_std; o.lqq_h_std = p.lq_h_std; o.ldq_h_std = p.ldq_h_std;
  o.hf_flux_radius_wb = p.hf_flux_radius_wb;
  return o;
}

v1::HfPoint ToProto(const IdentifiedPoint& r) {
  v1::HfPoint p;
  p.set_point_id(r.point_id); p.set_id_a(r.id_a); p.set_iq_a(r.iq_a); p.set_speed_rpm(r.speed_rpm);
  p.set_ld_h(r.ld_h); p.set_lq_h(r.lq_h);
  if (r.ldq_h) p.set_ldq_h(*r.ldq_h);
  p.set_ld_h_std(r.ld_h_std); p.set_lq_h_std(r.lq_h_std); p.set_ldq_h_std(r.ldq_h_std);
  p.set_temperature_c(r.temperature_c); p.set_reliable(r.reliable);
  if (r.hf_flux_radius_wb) p.set_hf_flux_radius_wb(*r.hf_flux_radius_wb);
  return p;
}

IdentifiedPoint FromProto(const v1::HfPoint& p) {
  IdentifiedPoint r;
  r.point_id = p.point_id();
  r.id_a = p.id_a(); r.iq_a = p.iq_a(); r.speed_rpm = p.speed_rpm();
  r.ld_h = p.ld_h(); r.lq_h = p.lq_h();
  if (p.has_ldq_h()) r.ldq_h = p.ldq_h();
  r.ld_h_std = p.ld_h_std(); r.lq_h_std = p.lq_h_std(); r.ldq_h_std = p.ldq_h_std();
  r.temperature_c = p.temperature_c();
  r.reliable = p.reliable();
  if (p.has_hf_flux_radius_wb()) r.hf_flux_radius_wb = p.hf_flux_radius_wb();
  return r;
}

absl::StatusOr<IdentifiedSet> IdentifySet(const io::RecordingSet& set, const ident::IdentifyOptions& options) {
  auto ids = ident::IdentifySet(set, options);
  if (!ids.ok()) return ids.status();
  IdentifiedSet out;
  out.results = std::move(*ids);
  for (const auto& r : out.results) {
    IdentifiedPoint p;
    if (FromIdentification(r, &p)) {
      p.hf_flux_radius_wb = InjectionFluxRadiusWb(set.manifest, r);
      out.points.push_back(std::move(p));
    } else {
      out.failures.push_back(absl::StrCat(r.point, ": ", r.failure));
    }
  }
  return out;
}

fit::FitData FitDataFromPoints(const storage::MotorRow& motor, const std::vector<IdentifiedPoint>& points) {
  fit::FitData d;
  d.serial = motor.serial;
  d.pole_pairs = motor.pole_pairs;
  // The store keeps 0 for a value the station did not state (the wire's unset).
  if (motor.rs_ohm > 0) d.rs_ohm = motor.rs_ohm;
  if (motor.psi_pm_wb > 0) d.psi_pm_prior_wb = motor.psi_pm_wb;
  for (const auto& p : points) d.inductances.push_back(ToObservation(p));
  return d;
}

absl::StatusOr<fit::FitData> FitDataFromSet(const io::RecordingSet& set, const ident::IdentifyOptions& options) {
  auto ids = ident::IdentifySet(set, options);
  if (!ids.ok()) return ids.status();
  return fit::FitDataFromRecording(set, *ids);
}

}  // namespace fluxcal::pipeline
