// The effect catalogue: the one owner of the effect vocabulary of
// docs/diagnosis-report.md. Each row gives the effect's report name, its
// parameters (report name, unit, neutral value, the scale diagnosis fits it
// on, the materiality floor below which no calibration decision changes),
// what it means, and how diagnosis explains it. The rows are a registry,
// one file per effect (simulation/catalogue/, which also binds the
// effect's --effects keys to the fields of Effects below and states its
// truth); the twin (Effects, ParseEffects), diagnosis (its candidates,
// scales, floors and explanations; one file per effect under
// diagnosis/effects/), the report and the docs read it.
#ifndef FLUXCAL_SIMULATION_EFFECTS_H_
#define FLUXCAL_SIMULATION_EFFECTS_H_

#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "simulation/bench_effect.h"

namespace fluxcal::sim {

// How a materiality floor is stated.
enum class FloorKind {
  kAbsolute,          // |value - neutral| >= floor, in the parameter's unit
  kRelativeNominal,   // |value - nominal| >= floor x |nominal| (nominal from the manifest)
  kBelow,             // 0 < value <= floor: a parallel resistance, the smaller the larger the effect
};

// What a floor is a multiple of, so that it means the same on every
// machine: a current sensor's offset of 0.25 A is 0.18 % of the twin's
// +-100 A plan and 1 % of a 26 A machine's, and 2 mOhm of HF resistance is
// 18 % of the twin's winding and 0.3 % of a 0.63 Ohm one. Drive-level
// quantities (a dead time, a delay, an angle, a gain) keep their own unit.
// The values are the set's (diagnosis/observations.cc, FloorScales):
enum class FloorScale {
  kNone,          // the parameter's own unit
  kRsNominal,     // the manifest's Rs [ohm]
  kCurrentMax,    // the largest current magnitude the set commands, points and rows [A]
  kUdc,           // the manifest's DC-link voltage [V]
  kTorqueMax,     // the largest |torque| the set's steady-state rows record [N m]
  kInductance,    // the mean identified HF inductance (Ld + Lq) / 2 [H]
  kReactance,     // the injection's angular frequency times that [ohm]
};

struct EffectParameter {
  std::string_view name;       // report name, e.g. "dead_time_s"
  std::string_view unit;       // SI unit ("s", "ohm", "rad", "1", "Wb", "H", "A", "V")
  double neutral = 0.0;        // value that switches the effect off (absolute parameters)
  double fit_scale = 1.0;      // diagnosis fits (value - neutral) / fit_scale (order one)
  double floor = 0.0;          // materiality floor (see FloorKind)
  FloorKind floor_kind = FloorKind::kAbsolute;
  // Smallest physically plausible value: a finding whose value lies below
  // it by more than 3 standard deviations is rejected as implausible (a
  // negative extra delay or HF resistance is a stand-in for something
  // else, not a fault).
  double plausible_min = -1e300;
  // The floor is `floor` times this scale of the set (kNone: as stated).
  FloorScale floor_scale = FloorScale::kNone;
  // Largest physically plausible value, judged as plausible_min: a current
  // sensor reading 40 % low on all three phases is a stand-in for
  // something else, not a sensor's gain error.
  double plausible_max = 1e300;
};

struct EffectRow {
  std::string_view name;          // report name, never changes meaning
  std::string_view meaning;       // one line, as in docs/diagnosis-report.md
  std::string_view explanation;   // diagnosis' explanation of a finding
  std::vector<EffectParameter> parameters;
  bool original = true;           // in version 1 of the vocabulary; false: documented extension
};

// All rows, in the report's order.
const std::vector<EffectRow>& EffectCatalogue();
// The row named `name`, or nullptr.
const EffectRow* FindEffect(std::string_view name);
// The parameter `param` of effect `effect` (dies loudly if absent: a
// programming error, not a data error).
const EffectParameter& EffectParam(std::string_view effect, std::string_view param);

// The twin's concealable effects, all off (neutral) by default. Field names
// follow the catalogue's parameter names.
struct Effects {
  double dead_time_s = 0.0;      // dead_time: residual uncompensated dead time
  double dead_time_i_th_a = 1.0; //   current scale of the soft sign (tanh)
  std::optional<double> rs_ohm;  // stator_resistance: true Rs (manifest keeps nominal)
  double r_hf_ohm = 0.0;         // hf_resistance: extra resistance seen by HF current
  double offset_rad = 0.0;       // position_offset: measured = true + offset
  double gain_a = 1.0, gain_b = 1.0, gain_c = 1.0;   // current_sensor_gain
  std::optional<double> psi_pm_wb;   // magnet_temperature: true psi_pm (manifest nominal)
  // magnet_temperature drifting: the magnets warm linearly over the test
  // (its points, then its steady-state rows, in recording order) by this
  // rise; psi_pm follows the motor's temperature coefficient.
  double magnet_temp_rise_k = 0.0;
  double delay_s = 0.0;          // sampling_delay: extra command delay
  int order = 0;                 // spatial_harmonics: order in theta_e
  double amplitude_h = 0.0;      //   and inductance amplitude
  double cross_saturation = 0.0; // cross_saturation strength g_cross_h [H]
  // Extensions of the vocabulary (docs/diagnosis-report.md).
  double offset_a_a = 0.0, offset_b_a = 0.0, offset_c_a = 0.0;   // current_sensor_offset
  double udc_sense_gain = 1.0;   // dc_link_sense_gain: measured Udc / true Udc
  double dr_a_ohm = 0.0, dr_b_ohm = 0.0, dr_c_ohm = 0.0;   // phase_resistance_imbalance
  double winding_temp_rise_k = 0.0;   // stator_temperature_drift: rise over the locked points
  double threshold_v = 0.0, slope_ohm = 0.0;   // inverter_voltage_drop: V_th sign(i_x) + r_on i_x per phase
  // position_sensor_harmonic: measured angle = true + offset + amplitude sin(2 theta_e + phase).
  double harmonic_amplitude_rad = 0.0, harmonic_phase_rad = 0.0;
  double r_fe_ohm = 0.0;         // iron_loss: parallel (iron-loss) resistance; 0: none
  // torque_loss: what the torque transducer reads below the air-gap torque,
  // friction_nm sign(n) + viscous_nm_per_rad_s w_m (physics/torque.h).
  double friction_nm = 0.0, viscous_nm_per_rad_s = 0.0;
  // Physics outside the catalogue (simulation/bench_effect.h): the twin
  // applies it, diagnosis never models it.
  BenchEffects unmodelled;
};

// The angle sensor's reading error at the true electrical angle: the
// position_offset plus the position_sensor_harmonic (one home for both the
// bench and the replays).
double AngleSensorError(const Effects& e, double theta_true_rad);

// Parses "dead_time_s=2e-6,offset_rad=0.05,..." (keys: Effects' fields,
// noise_a, and the bench effects' parameters, which switch those on).
// Unknown keys are errors listing the known ones.
absl::Status ParseEffects(const std::string& spec, Effects* effects, double* noise_a);
// Report names of the effects that are on, in catalogue order.
std::vector<std::string> ActiveEffectNames(const Effects& e);
// Parameters of an active effect as the truth file states them.
std::map<std::string, double> EffectParameters(const Effects& e, std::string_view effect);

}  // namespace fluxcal::sim

#endif  // FLUXCAL_SIMULATION_EFFECTS_H_
