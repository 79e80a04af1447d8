#include "simulation/effects.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "simulation/frames.h"

namespace fluxcal::sim {

// Scales and floors: the scale puts each fitted parameter at order one
// (what Ceres' trust region sees); the floor is a fraction of the tolerance
// a calibration is held to (dead time 20 %, resistance 15 %, offset 0.5
// electrical degrees, gains 0.5 %, psi_pm 1 %), below which no calibration
// decision changes however precisely the data pin the value down.
const std::vector<EffectRow>& EffectCatalogue() {
  static const std::vector<EffectRow> rows = {
      {"dead_time",
       "uncompensated inverter dead time / device drop: voltage error following the sign of each phase current",
       "voltage error that follows the sign of each phase current: the held DC commands depart from Rs i by a "
       "current-sign pattern and the HF response is distorted where a phase current lingers near zero "
       "(uncompensated inverter dead time or device drop)",
       {{"dead_time_s", "s", 0.0, 1e-6, 0.1e-6}}},
      {"cross_saturation", "psi_d depends on iq and psi_q on id; Ldq != 0",
       "the HF response needs Ldq != 0 and Ldd depending on iq: psi_d depends on iq and psi_q on id (cross "
       "saturation), modelled by cross terms of the co-energy",
       {}},
      {"stator_resistance", "winding resistance differs from nominal",
       "the DC voltage that holds each standstill current scales with a resistance other than the nominal one",
       {{"rs_ohm", "ohm", 0.0, 1e-3, 0.03, FloorKind::kRelativeNominal, 0.0}}},
      {"hf_resistance", "extra series resistance at the injection frequency (eddy currents, iron loss)",
       "the positive-sequence HF current leads the injected voltage by more than the winding resistance "
       "explains: extra series resistance at the injection frequency (eddy currents)",
       {{"r_hf_ohm", "ohm", 0.0, 1e-3, 0.002, FloorKind::kAbsolute, 0.0}}},
      {"differential_inductance",
       "differential (HF) inductance used where apparent inductance / flux linkage is needed, or the reverse",
       "the mismatch between HF-identified and steady-state inductance grows with current: the differential "
       "inductance was taken as the apparent one",
       {}},
      {"position_offset", "angle sensor offset: measured = true + offset",
       "the saliency (negative-sequence phase) and the steady-state voltages are rotated by a constant angle: "
       "the angle sensor reads true + offset",
       {{"offset_rad", "rad", 0.0, 1e-2, 0.25 * kPi / 180}}},
      {"current_sensor_gain", "phase current sensors with unequal gains (measured = gain x true)",
       "a spurious HF component fixed in the stationary frame (not following 2 theta_e) and held currents off "
       "by a sensor gain: the phase current sensors have unequal gains (their mean is separated from Rs by the "
       "nominal Rs)",
       {{"gain_a", "1", 1.0, 1e-2, 0.0025}, {"gain_b", "1", 1.0, 1e-2, 0.0025}, {"gain_c", "1", 1.0, 1e-2, 0.0025}}},
      {"magnet_temperature", "magnet flux linkage differs from nominal / drifts with temperature",
       "back-EMF in the steady-state voltages and torque differ from the nominal magnet flux (magnet "
       "temperature or magnetisation)",
       {{"psi_pm_wb", "Wb", 0.0, 1e-2, 0.005, FloorKind::kRelativeNominal},
        // A drift (documented extension): psi_pm at the first and last
        // steady-state row in recording order.
        {"psi_pm_start_wb", "Wb", 0.0, 1e-2, 0.005, FloorKind::kRelativeNominal},
        {"psi_pm_end_wb", "Wb", 0.0, 1e-2, 0.005, FloorKind::kRelativeNominal}}},
      {"sampling_delay", "extra delay between voltage command and its application",
       "HF current lags the command by a phase proportional to frequency and the steady-state voltages are "
       "rotated by w_e times the same time: extra delay between command and inverter",
       {{"delay_s", "s", 0.0, 1e-6, 2e-6, FloorKind::kAbsolute, 0.0}}},
      {"spatial_harmonics", "inductance varies with rotor angle beyond the 2 theta_e term",
       "the identified inductance at standstill varies with rotor angle as cos(order theta_e), beyond the "
       "saliency's 2 theta_e",
       {{"order", "1", 0.0, 1.0, 0.0}, {"amplitude_h", "H", 0.0, 1e-6, 1e-6}}},
      // ---- Extensions (docs/diagnosis-report.md, "Documented extensions").
      // A current sensor's DC offset: 0.1 % of a 250 A sensor's range is what
      // an EOL offset calibration is held to; below it no table changes.
      {"current_sensor_offset", "phase current sensors with a DC offset (measured = true + offset)",
       "held currents at standstill are off by a current fixed in the stationary frame (it does not follow the "
       "rotor angle) and torque at speed disagrees with the commanded current: the phase current sensors have "
       "DC offsets",
       {{"offset_a_a", "A", 0.0, 0.1, 0.25}, {"offset_b_a", "A", 0.0, 0.1, 0.25}, {"offset_c_a", "A", 0.0, 0.1, 0.25}},
       false},
      // A DC-link voltage measurement off by a gain: the modulator divides
      // the command by the measured voltage, so every applied voltage is
      // scaled by 1/gain while currents and torque are untouched. 1 %: the
      // tolerance of a production voltage divider; below it the voltage
      // tables move less than psi_pm's own 1 % tolerance.
      {"dc_link_sense_gain", "DC-link voltage measurement off by a gain (measured = gain x true)",
       "every applied voltage (held DC, HF injection, back-EMF) is the command scaled by one common factor while "
       "the torque agrees with the currents: the DC-link voltage is measured with a gain error, so the "
       "modulator applies command / gain",
       {{"udc_sense_gain", "1", 1.0, 1e-2, 0.01}},
       false},
      // A bad joint (crimp, weld, terminal) adds resistance to one phase.
      // Its common part is stator_resistance; the rest is reported as a
      // zero-sum set. 1 mOhm: 8 % of these windings' Rs, about the
      // resistance spread a production line accepts between phases.
      {"phase_resistance_imbalance", "unequal phase resistances, e.g. a bad joint (extra ohm per phase)",
       "the DC voltage that holds a standstill current depends on the current's direction in the stationary "
       "frame (twice the angle), with no matching HF component in the stationary frame and no change at speed: "
       "the phase resistances differ (a bad joint)",
       {{"dr_a_ohm", "ohm", 0.0, 1e-3, 1e-3}, {"dr_b_ohm", "ohm", 0.0, 1e-3, 1e-3}, {"dr_c_ohm", "ohm", 0.0, 1e-3, 1e-3}},
       false},
      // The winding warms during the test (copper +0.393 %/K): Rs grows
      // along the test's order. 5 K: 2 % of Rs, below stator_resistance's
      // own 3 % floor.
      {"stator_temperature_drift",
       "the winding warms during the test: Rs rises linearly over the locked points (copper +0.393 %/K)",
       "the resistance the held DC voltages need rises with the order the points were recorded in: the winding "
       "warmed during the test",
       {{"winding_temp_rise_k", "K", 0.0, 1.0, 5.0}},
       false},
      // The switches' on-state voltage: a threshold V_th sign(i_x) (IGBT
      // collector-emitter knee, diode forward voltage) plus a slope r_on i_x,
      // per phase, opposing the current. With one DC-link voltage the
      // threshold has exactly the dead time's current-sign pattern
      // (Td = V_th Ts / Udc); the dead-time error scales with Udc and the
      // threshold does not, so a plan that repeats locked points at a second
      // Udc separates them. The slope is in series with Rs in every response
      // seen through the inverter's commands (docs/diagnosis.md): diagnosis
      // names it as an alternative of stator_resistance, never alone.
      // 0.05 V: the dead time's own floor (0.1 us) at 50 V and 10 kHz.
      {"inverter_voltage_drop",
       "inverter on-state voltage drop: threshold V_th sign(i_x) plus slope r_on i_x per phase",
       "the voltage that holds each standstill current departs from Rs i by a current-sign pattern that does not "
       "scale with the DC-link voltage (the points repeated at a second Udc show the same step): the inverter's "
       "switches drop a threshold voltage (IGBT knee / diode forward voltage), not a dead time",
       {{"threshold_v", "V", 0.0, 0.1, 0.05, FloorKind::kAbsolute, 0.0},
        {"slope_ohm", "ohm", 0.0, 1e-3, 1e-3, FloorKind::kAbsolute, 0.0}},
       false},
      // A production defect of the angle sensor an EOL station calibrates
      // out: a resolver with unequal sine/cosine winding amplitudes (or an
      // encoder disc mounted off-centre on a sensor with the motor's pole
      // count) reads true + a sin(2 theta_e + phase). position_offset is its
      // constant part only. 0.25 electrical degrees, as position_offset: the
      // torque error it leaves is then below the tables' tolerance. The
      // phase alone is never material (infinite floor): the amplitude is.
      {"position_sensor_harmonic",
       "angle sensor error at twice the electrical angle (resolver amplitude imbalance, eccentric encoder disc): "
       "measured = true + amplitude sin(2 theta_e + phase)",
       "the saliency's phase (negative-sequence current) at standstill swings with the rotor angle as "
       "sin(2 theta_e), not by one constant angle: the angle sensor reads true + amplitude sin(2 theta_e + phase) "
       "(a resolver's unequal winding amplitudes or an eccentric encoder disc)",
       {{"harmonic_amplitude_rad", "rad", 0.0, 1e-2, 0.25 * kPi / 180, FloorKind::kAbsolute, 0.0},
        {"harmonic_phase_rad", "rad", 0.0, 1.0, std::numeric_limits<double>::infinity()}},
       false},
      // Iron loss (eddy currents and hysteresis in the laminations) as a
      // resistance in parallel with the magnetising branch: the loss current
      // g e makes no flux and no torque. At the injection frequency it is an
      // HF resistance matrix w^2 g L^2 (unlike hf_resistance: larger on the
      // axis of larger inductance, falling with saturation); at speed the
      // back-EMF drives g w J psi, which the measured current includes and
      // the torque does not. Fitted as the conductance g = 1 / R_fe (0 = none,
      // the neutral); material below 500 ohm, where w_i^2 g L^2 reaches
      // hf_resistance's 2 mOhm at 500 Hz and 0.3 mH.
      {"iron_loss",
       "iron loss as a resistance in parallel with the magnetising branch (R_fe): loss current without flux or torque",
       "the HF resistance is larger on the axis of larger inductance and falls with saturation (w^2 L^2 / R_fe), and "
       "at speed the measured current exceeds what the torque needs by the back-EMF over a resistance: iron loss "
       "in a resistance R_fe parallel to the magnetising inductance",
       // fit_scale: of the conductance, in S.
       {{"r_fe_ohm", "ohm", 0.0, 0.01, 500.0, FloorKind::kBelow, 0.0}},
       false},
      // Every torque transducer sits behind bearings and seals: it reads the
      // air-gap torque less friction (opposing the rotation) and drag
      // (growing with speed), and has a zero of its own (one direction of
      // rotation cannot tell it from the friction). Fitted on the
      // steady-state rows' torque only (the voltages pin the magnet flux and
      // the currents). 0.05 N m: the torque rows' own uncertainty (0.02 N m
      // + 0.5 %) over a few rows, 0.3 % of these machines' rated torque,
      // below which no torque table changes; drag as 0.05 N m at 1000 rpm.
      {"torque_loss",
       "mechanical loss between the air gap and the torque transducer: friction T_f sign(n) (with the transducer's "
       "zero) plus drag b w_m",
       "the measured torque falls short of the air-gap torque that the voltages and currents give by an amount that "
       "does not scale with the current and grows with the speed, while the voltages agree with the magnet flux: "
       "friction and drag between the air gap and the torque transducer (bearings, seals, windage), or the "
       "transducer's zero",
       {{"friction_nm", "N m", 0.0, 0.1, 0.05},
        {"viscous_nm_per_rad_s", "N m s", 0.0, 1e-3, 0.05 / (1000 * 2 * kPi / 60), FloorKind::kAbsolute, 0.0}},
       false},
  };
  return rows;
}

double AngleSensorError(const Effects& e, double theta_true_rad) {
  return e.offset_rad + e.harmonic_amplitude_rad * std::sin(2 * theta_true_rad + e.harmonic_phase_rad);
}

const EffectRow* FindEffect(std::string_view name) {
  for (const auto& r : EffectCatalogue()) {
    if (r.name == name) return &r;
  }
  return nullptr;
}

const EffectParameter& EffectParam(std::string_view effect, std::string_view param) {
  const EffectRow* row = FindEffect(effect);
  if (row != nullptr) {
    for (const auto& p : row->parameters) {
      if (p.name == param) return p;
    }
  }
  std::fprintf(stderr, "effect catalogue: no parameter '%.*s' of effect '%.*s'\n", static_cast<int>(param.size()),
               param.data(), static_cast<int>(effect.size()), effect.data());
  std::abort();
}

namespace {

// The twin's key -> field map. Optional fields (rs_ohm, psi_pm_wb) and the
// integer order are handled by the parser below.
std::map<std::string, double*> DoubleFields(Effects* e) {
  return {{"dead_time_s", &e->dead_time_s},   {"dead_time_i_th_a", &e->dead_time_i_th_a},
          {"r_hf_ohm", &e->r_hf_ohm},         {"offset_rad", &e->offset_rad},
          {"gain_a", &e->gain_a},             {"gain_b", &e->gain_b},
          {"gain_c", &e->gain_c},             {"delay_s", &e->delay_s},
          {"amplitude_h", &e->amplitude_h},   {"cross_saturation", &e->cross_saturation},
          {"offset_a_a", &e->offset_a_a},     {"offset_b_a", &e->offset_b_a},
          {"offset_c_a", &e->offset_c_a},     {"udc_sense_gain", &e->udc_sense_gain},
          {"dr_a_ohm", &e->dr_a_ohm},         {"dr_b_ohm", &e->dr_b_ohm},
          {"dr_c_ohm", &e->dr_c_ohm},         {"winding_temp_rise_k", &e->winding_temp_rise_k},
          {"threshold_v", &e->threshold_v},   {"slope_ohm", &e->slope_ohm},
          {"harmonic_amplitude_rad", &e->harmonic_amplitude_rad},
          {"harmonic_phase_rad", &e->harmonic_phase_rad},
          {"r_fe_ohm", &e->r_fe_ohm},         {"magnet_temp_rise_k", &e->magnet_temp_rise_k},
          {"friction_nm", &e->friction_nm},   {"viscous_nm_per_rad_s", &e->viscous_nm_per_rad_s}};
}

}  // namespace

absl::Status ParseEffects(const std::string& spec, Effects* e, double* noise_a) {
  if (spec.empty()) return absl::OkStatus();
  Effects scratch;
  auto fields = DoubleFields(e);
  for (absl::string_view item : absl::StrSplit(spec, ',', absl::SkipEmpty())) {
    std::vector<std::string> kv = absl::StrSplit(item, absl::MaxSplits('=', 1));
    if (kv.size() != 2) {
      return absl::InvalidArgumentError(absl::StrCat("flag --effects: expected key=value, got '", item, "'"));
    }
    double v;
    if (!absl::SimpleAtod(kv[1], &v) || !std::isfinite(v)) {
      return absl::InvalidArgumentError(
          absl::StrCat("flag --effects: field '", kv[0], "': expected a number, got '", kv[1], "'"));
    }
    const std::string& k = kv[0];
    if (auto it = fields.find(k); it != fields.end()) *it->second = v;
    else if (k == "rs_ohm") e->rs_ohm = v;
    else if (k == "psi_pm_wb") e->psi_pm_wb = v;
    else if (k == "order") e->order = static_cast<int>(v);
    else if (k == "noise_a" && noise_a != nullptr) *noise_a = v;
    else if (SetBenchEffectParameter(k, v, &e->unmodelled).ok()) continue;
    else {
      std::vector<std::string> known;
      for (const auto& [name, ptr] : DoubleFields(&scratch)) known.push_back(name);
      for (const char* x : {"rs_ohm", "psi_pm_wb", "order", "noise_a"}) known.push_back(x);
      for (const auto& x : BenchEffectParameterNames()) known.push_back(x);
      return absl::InvalidArgumentError(
          absl::StrCat("flag --effects: unknown key '", k, "' (known: ", absl::StrJoin(known, ", "), ")"));
    }
  }
  return absl::OkStatus();
}

std::map<std::string, double> EffectParameters(const Effects& e, std::string_view effect) {
  if (effect == "dead_time") return {{"dead_time_s", e.dead_time_s}, {"i_th_a", e.dead_time_i_th_a}};
  if (effect == "cross_saturation") return {{"strength_h", e.cross_saturation}};
  if (effect == "stator_resistance") return {{"rs_ohm", e.rs_ohm.value_or(0.0)}};
  if (effect == "hf_resistance") return {{"r_hf_ohm", e.r_hf_ohm}};
  if (effect == "position_offset") return {{"offset_rad", e.offset_rad}};
  if (effect == "current_sensor_gain") return {{"gain_a", e.gain_a}, {"gain_b", e.gain_b}, {"gain_c", e.gain_c}};
  if (effect == "magnet_temperature") return {{"psi_pm_wb", e.psi_pm_wb.value_or(0.0)}};
  if (effect == "sampling_delay") return {{"delay_s", e.delay_s}};
  if (effect == "spatial_harmonics") return {{"order", e.order}, {"amplitude_h", e.amplitude_h}};
  if (effect == "current_sensor_offset") {
    return {{"offset_a_a", e.offset_a_a}, {"offset_b_a", e.offset_b_a}, {"offset_c_a", e.offset_c_a}};
  }
  if (effect == "dc_link_sense_gain") return {{"udc_sense_gain", e.udc_sense_gain}};
  if (effect == "phase_resistance_imbalance") {
    return {{"dr_a_ohm", e.dr_a_ohm}, {"dr_b_ohm", e.dr_b_ohm}, {"dr_c_ohm", e.dr_c_ohm}};
  }
  if (effect == "stator_temperature_drift") return {{"winding_temp_rise_k", e.winding_temp_rise_k}};
  if (effect == "inverter_voltage_drop") return {{"threshold_v", e.threshold_v}, {"slope_ohm", e.slope_ohm}};
  if (effect == "iron_loss") return {{"r_fe_ohm", e.r_fe_ohm}};
  if (effect == "torque_loss") return {{"friction_nm", e.friction_nm}, {"viscous_nm_per_rad_s", e.viscous_nm_per_rad_s}};
  if (effect == "position_sensor_harmonic") {
    return {{"harmonic_amplitude_rad", e.harmonic_amplitude_rad}, {"harmonic_phase_rad", e.harmonic_phase_rad}};
  }
  return {};
}

std::vector<std::string> ActiveEffectNames(const Effects& e) {
  std::vector<std::string> out;
  for (const auto& row : EffectCatalogue()) {
    bool on = false;
    const std::string name(row.name);
    if (name == "cross_saturation") on = e.cross_saturation != 0;
    else if (name == "stator_resistance") on = e.rs_ohm.has_value();
    else if (name == "magnet_temperature") on = e.psi_pm_wb.has_value() || e.magnet_temp_rise_k != 0.0;
    else if (name == "spatial_harmonics") on = e.order != 0 && e.amplitude_h != 0;
    else if (name == "position_sensor_harmonic") on = e.harmonic_amplitude_rad != 0;
    else {
      // Any catalogue parameter away from its neutral value.
      const auto values = EffectParameters(e, name);
      for (const auto& p : row.parameters) {
        const auto it = values.find(std::string(p.name));
        if (it != values.end() && it->second != p.neutral) on = true;
      }
    }
    if (on) out.push_back(name);
  }
  return out;
}

}  // namespace fluxcal::sim
