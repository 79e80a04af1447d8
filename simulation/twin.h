// The digital twin: a saturated IPMSM (flux linkages as states), a
// per-PWM-period average inverter with dead time, a bench with PI current
// control and rotating HF injection, and sensors. Every physical effect is a
// named, parameterised, switchable term (the catalogue of
// simulation/effects.h). Code: plant.{h,cc}, bench.{h,cc}, replay.cc,
// twin_json.cc. See docs/simulation.md for equations and timing.
#ifndef FLUXCAL_SIMULATION_TWIN_H_
#define FLUXCAL_SIMULATION_TWIN_H_

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "io/recording_set.h"
#include "simulation/effects.h"
#include "simulation/magnetic_model.h"
#include "simulation/saturation_model.h"

namespace fluxcal::sim {

// The true motor. Magnetics: the analytic co-energy model of
// saturation_model.h with a magnet temperature coefficient.
struct MotorParams {
  int pole_pairs = 4;
  double rs_ohm = 0.0110;
  SaturationParams sat;                  // g_cross_h = 0: no cross saturation
  double psi_pm_temp_coeff_per_k = -0.0012;   // NdFeB, -0.12 %/K
};

// Implements MagneticModel for MotorParams (plus an optional rotor-angle
// dependent term used by the spatial_harmonics effect, outside this class).
class AnalyticMotor : public MagneticModel {
 public:
  explicit AnalyticMotor(const MotorParams& p) : p_(p) {}
  FluxLinkage Flux(double id_a, double iq_a, double temperature_c = 25.0) const override;
  DifferentialInductance Inductance(double id_a, double iq_a,
                                    double temperature_c = 25.0) const override;
  const MotorParams& params() const { return p_; }

 private:
  MotorParams p_;
};

struct DriveParams {
  double udc_v = 50.0;
  double f_pwm_hz = 10000.0;           // = sample rate
  double nominal_dead_time_s = 1e-6;   // declared in the manifest, compensated
  int substeps = 10;                   // RK4 sub-steps per PWM period
};

struct SensorParams {
  double noise_a = 0.05;               // current noise sigma per phase
  double adc_lsb_a = 250.0 * 2 / 4096; // 12 bit over +-250 A
  int encoder_counts_per_mech_rev = 4096;   // 0: ideal angle sensor
  double udc_noise_v = 0.02;
};

struct ControlParams {
  double bandwidth_hz = 80.0;
  double integral_corner_hz = 10.0;
  double ld_nominal_h = 0.18e-3, lq_nominal_h = 0.35e-3;
  // A controller tuned from the machine's own magnetics, as drives with a
  // flux map are: proportional gains on the differential inductance at each
  // point's reference current, kp = 2 pi bandwidth L(i_ref) (floored at
  // 10 % of the nominal: a negative or vanishing L near zero current), and
  // decoupling by the map's back-EMF w_e psi(i) at the measured current.
  // Off: kp and decoupling on ld/lq_nominal_h at every point. A fixed gain
  // tuned at the unsaturated L puts the crossover of a machine whose Lqq
  // falls 10x through a bridge knee 10x higher, past what the
  // one-injection-period feedback average allows; the loop oscillates into
  // the voltage limit (docs/simulation.md).
  bool gain_scheduled = false;
};

struct InjectionParams {
  double amplitude_v = 5.0;
  double frequency_hz = 500.0;
};

struct PlanPoint {
  std::string id;
  double id_ref_a = 0, iq_ref_a = 0, speed_rpm = 0;
  double theta_e_rad = 0.0;            // locked rotor angle (speed = 0) / start angle
  double temperature_c = 25.0;
  double udc_v = 0.0;                  // DC-link voltage of this point; 0: the drive's
  // The pole pair the rotor stands in (0 .. pole_pairs - 1): the mechanical
  // angle is (theta_e_rad + 2 pi sector) / pole_pairs. Locked points at one
  // electrical angle in different sectors differ only mechanically
  // (simulation/bench_effect.h).
  int sector = 0;
};
struct PlanSteadyState {
  double id_ref_a = 0, iq_ref_a = 0, speed_rpm = 1000, temperature_c = 25.0;
};
struct Plan {
  std::vector<PlanPoint> points;
  std::vector<PlanSteadyState> steady_state;
  double settle_s = 0.03;
  double record_s = 0.1;
};

// The paper's grid (id = -100..0 A, iq = 0..100 A, 20 A steps; 36 locked
// points at spread angles), rotating points at 200..1000 rpm, and steady
// state rows at 1000..2000 rpm.
Plan DefaultPlan();

// `plan` with every `every`-th locked point repeated right after itself at
// DC-link voltage `udc_v` (ids suffixed "u"). The dead-time voltage error
// scales with Udc and a switch's threshold voltage does not: the repeated
// points are what separates dead_time from inverter_voltage_drop
// (docs/diagnosis.md). Interleaved, not appended, so that a winding warming
// over the test does not pass for a change with Udc.
Plan WithSecondUdc(Plan plan, double udc_v, int every = 3);

struct TwinConfig {
  std::string serial = "IPM-SIM-000001";
  MotorParams motor;
  // Optional second magnetics family (e.g. a GriddedFluxMap): when set, the
  // plant's flux linkage comes from it instead of motor.sat (motor.sat
  // psi_pm_wb still states the manifest's nominal value).
  std::shared_ptr<const MagneticModel> magnetics;
  DriveParams drive;
  SensorParams sensors;
  ControlParams control;
  InjectionParams injection;
  Effects effects;
  uint64_t seed = 1;
};

// Truth per point: mean true current of the recorded window and the exact
// flux linkages and Jacobian there.
struct TruthPoint {
  std::string id;
  double id_true_a = 0, iq_true_a = 0, speed_rpm = 0, temperature_c = 25;
  double psi_d_wb = 0, psi_q_wb = 0, ldd_h = 0, lqq_h = 0, ldq_h = 0;
  double ld_app_h = 0, lq_app_h = 0, torque_nm = 0, psi_pm_wb = 0;
  // Mean voltage the inverter applied over the window, true dq frame.
  double applied_ud_v = 0, applied_uq_v = 0;
  // Time averages over the window (trapezoidal over sub-steps), true frame.
  double avg_id_a = 0, avg_iq_a = 0, avg_psi_d_wb = 0, avg_psi_q_wb = 0;
  double dpsi_d_dt = 0, dpsi_q_dt = 0;   // (psi_end - psi_start) / window
};

struct SimulationResult {
  io::RecordingSet set;
  std::vector<TruthPoint> truth_points;
  std::vector<TruthPoint> truth_steady_state;
  bool clipped = false;
};

absl::StatusOr<SimulationResult> Simulate(const TwinConfig& config, const Plan& plan);

// Truth file (format fluxcal.truth.v1): effects with parameters, per point and
// per steady-state row truth.
std::string TruthJson(const TwinConfig& config, const SimulationResult& result);

// Motor/plan JSON (docs/simulation.md). Missing keys keep defaults; unknown
// keys are errors naming file and field.
absl::Status LoadMotorJson(const std::string& path, TwinConfig* config);
absl::StatusOr<Plan> LoadPlanJson(const std::string& path);

// Open-loop replay of a recording: the recorded voltage commands, applied
// one PWM period late as in the bench (docs/simulation.md), drive the model
// plant along the recorded angle trajectory (less the effect's offset), from
// the current measured in the first sample. Returns the simulated measured
// phase currents aligned sample by sample with the recording. Deterministic
// (no noise). What diagnosis would fit through at waveform level.
struct ReplayPoint {
  std::string point;
  std::vector<double> ia_a, ib_a, ic_a;
  // What the modelled angle sensor adds to the true angle beyond its
  // constant offset, per sample (rad; AngleSensorError less offset_rad):
  // the rotor-angle channel's model of the reading (diagnosis/waveform.cc).
  std::vector<double> angle_error_rad;
  double residual_rms_a = 0;   // vs the recorded currents
};
struct ReplayOptions {
  double rs_ohm = 0.011;
  Effects effects;             // drive/sensor effects to include
  int substeps = 10;
};
absl::StatusOr<std::vector<ReplayPoint>> ReplayOpenLoop(const io::RecordingSet& set, const MagneticModel& model,
                                                        const ReplayOptions& options);

// Closed-loop replay: every recorded test run again on the twin's bench —
// the manifest's references, speed and injection, the bench controller of
// `control` (a recording does not say which gains its bench used; these are
// the assumption), the controller reading the recorded angle, the plant
// driven by `model` with `effects` — aligned with the recording (plant
// angle and injection phase at its first sample) after `settle_s`. Returns
// the simulated measured phase currents sample by sample and their RMS
// difference from the recorded ones. Unlike the open-loop replay, a wrong
// model here shows up as the controller's reaction to it, as on the bench.
struct ClosedLoopReplayOptions {
  double rs_ohm = 0.011;
  Effects effects;
  ControlParams control;
  double settle_s = 0.03;
  int substeps = 10;
};
absl::StatusOr<std::vector<ReplayPoint>> ReplayClosedLoop(const io::RecordingSet& set, const MagneticModel& model,
                                                          const ClosedLoopReplayOptions& options);

// A serial-specific production spread: a few percent on saturation
// parameters, psi_pm and Rs, reproducible from the seed.
MotorParams PerturbForProduction(const MotorParams& nominal, uint64_t seed);

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_TWIN_H_
