// The twin's bench (internal to simulation/): one test run at an operating
// point -- PI current control, injection, inverter, plant, sensors -- and
// the plant built from a TwinConfig. Used by Simulate (bench.cc) and the
// closed-loop replay (replay.cc).
#ifndef FLUXCAL_SIMULATION_BENCH_H_
#define FLUXCAL_SIMULATION_BENCH_H_

#include <random>
#include <vector>

#include "io/recording_set.h"
#include "simulation/plant.h"
#include "simulation/twin.h"

namespace fluxcal::sim {

struct PointRun {
  io::Waveform wave;
  double mean_id_true = 0, mean_iq_true = 0;
  double mean_ud_cmd = 0, mean_uq_cmd = 0;    // controller frame, fundamental
  double mean_ud_applied = 0, mean_uq_applied = 0;   // true frame, incl. errors
  double mean_torque_nm = 0;
  double avg_id = 0, avg_iq = 0, avg_psd = 0, avg_psq = 0, dpsd = 0, dpsq = 0;
  double mean_id_meas = 0, mean_iq_meas = 0;   // what the bench's sensors report
  bool clipped = false;
  // What the bench held over the recorded window, as steady_state.csv's
  // extension columns state it (docs/recording-format.md): RMS of the
  // measured dq current's deviation from its window mean, A; share of the
  // control periods in which the modulator limited the command; share in
  // which the PI pair's output was clamped (its only limit is the
  // modulator's: the same periods, less those where only the injection
  // carried the command over the limit).
  double current_ripple_a = 0;
  double voltage_limited_share = 0;
  double controller_saturated_share = 0;
};

// Optional alignment of a run with a recording (closed-loop replay): the
// injection's phase at t = 0 of the run, and the recorded angle the
// controller reads during the record window.
struct RunAlignment {
  double injection_phase_rad = 0.0;
  const std::vector<double>* theta_meas_rad = nullptr;
};

PointRun RunPoint(const TwinConfig& cfg, const PlantModel& m, double id_ref, double iq_ref,
                  double speed_rpm, double theta0, double temperature_c, bool inject,
                  double settle_s, double record_s, std::mt19937_64* rng,
                  const RunAlignment& align = {});

// The plant of the true motor of `cfg` at a magnet temperature.
PlantModel MakePlant(const TwinConfig& cfg, double temperature_c);

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_BENCH_H_
