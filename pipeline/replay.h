// Replay of a recording set through the digital twin with a calibration as
// the motor's magnetics (`fluxcal replay`): per point, the RMS difference
// between simulated and recorded phase currents, open loop (the recorded
// commands drive the plant) or closed loop (the manifest's references
// through the twin's bench controller, whose gains are the caller's
// assumption). docs/simulation.md; the twin's types stay behind this header.
#ifndef FLUXCAL_PIPELINE_REPLAY_H_
#define FLUXCAL_PIPELINE_REPLAY_H_

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "io/recording_set.h"

namespace fluxcal::pipeline {

struct ReplayRequest {
  bool closed_loop = false;
  // Closed loop: the bench controller assumed; unset: the twin's defaults.
  std::optional<double> bandwidth_hz, ld_nominal_h, lq_nominal_h, settle_s;
};

struct ReplayedPoint {
  std::string point;
  double id_ref_a = 0, iq_ref_a = 0, speed_rpm = 0;   // the manifest's
  double residual_rms_a = 0;                          // vs the recorded currents
};

struct ReplayResult {
  double rs_ohm = 0;   // the calibration's resistance if it has one, else the manifest's (else 0)
  std::vector<ReplayedPoint> points;
  double residual_rms_a = 0;   // over every sample of every point
  // Closed loop: the controller used.
  double bandwidth_hz = 0, ld_nominal_h = 0, lq_nominal_h = 0, settle_s = 0;
};

absl::StatusOr<ReplayResult> ReplayRecording(const io::RecordingSet& set, const fit::Calibration& cal,
                                             const ReplayRequest& request);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_REPLAY_H_
