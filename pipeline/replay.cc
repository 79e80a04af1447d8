#include "pipeline/replay.h"

#include <cmath>

#include "simulation/twin.h"

namespace fluxcal::pipeline {

absl::StatusOr<ReplayResult> ReplayRecording(const io::RecordingSet& set, const fit::Calibration& cal,
                                             const ReplayRequest& request) {
  ReplayResult out;
  out.rs_ohm = cal.rs_ohm().value_or(set.manifest.motor.rs_ohm.value_or(0.0));
  absl::StatusOr<std::vector<sim::ReplayPoint>> rep;
  if (request.closed_loop) {
    sim::ClosedLoopReplayOptions co;
    co.rs_ohm = out.rs_ohm;
    if (request.bandwidth_hz) co.control.bandwidth_hz = *request.bandwidth_hz;
    if (request.ld_nominal_h) co.control.ld_nominal_h = *request.ld_nominal_h;
    if (request.lq_nominal_h) co.control.lq_nominal_h = *request.lq_nominal_h;
    if (request.settle_s) co.settle_s = *request.settle_s;
    out.bandwidth_hz = co.control.bandwidth_hz;
    out.ld_nominal_h = co.control.ld_nominal_h;
    out.lq_nominal_h = co.control.lq_nominal_h;
    out.settle_s = co.settle_s;
    rep = sim::ReplayClosedLoop(set, cal, co);
  } else {
    sim::ReplayOptions oo;
    oo.rs_ohm = out.rs_ohm;
    rep = sim::ReplayOpenLoop(set, cal, oo);
  }
  if (!rep.ok()) return rep.status();
  double se = 0;
  size_t n = 0;
  for (size_t k = 0; k < rep->size(); ++k) {
    const auto& r = (*rep)[k];
    const auto& spec = set.manifest.points[k];
    se += r.residual_rms_a * r.residual_rms_a * r.ia_a.size();
    n += r.ia_a.size();
    out.points.push_back({r.point, spec.id_ref_a, spec.iq_ref_a, spec.speed_rpm, r.residual_rms_a});
  }
  out.residual_rms_a = n ? std::sqrt(se / n) : 0.0;
  return out;
}

}  // namespace fluxcal::pipeline
