// What physics could make a located mismatch (docs/diagnosis.md, "Naming
// what is not modelled"): for each kind of mismatch -- a region of a
// summarised observable, a pattern over the rotor angle, a line in the
// waveforms' residual at a multiple of the electrical, mechanical or
// injection frequency or at a fixed frequency, in the phase currents, the
// zero sequence or the recorded angle -- the hypotheses whose signature it
// matches, most likely first, each with its catalogue name when the
// catalogue models it and what it would show elsewhere: the test that tells
// the hypotheses apart. The ranking is by how specific the signature is
// (an effect whose signature is exactly this pattern first).
#include <algorithm>
#include <cmath>

#include "absl/strings/str_format.h"
#include "diagnosis/internal.h"

namespace fluxcal::diag::detail {
namespace {

using H = Hypothesis;

bool Near(double f, double g, double tol) { return std::abs(f - g) <= tol; }

std::vector<H> ForLine(const Mismatch& m, int pole_pairs) {
  std::vector<H> h;
  const int k = m.order;
  if (m.signal == "zero_sequence_current") {
    // Sensors first; a fixed frequency also names its likely source below.
    h.push_back({"a current sensor effect: one phase's sensor adds or loses what the others do not (gain, offset, "
                 "nonlinearity, interference, crosstalk from a neighbouring busbar); a star winding's currents sum "
                 "to zero, so the zero sequence is the sensors' own",
                 "", "follow one phase's current (or a fixed frequency) at every point, at standstill and at speed alike"});
    if (m.kind != "fixed_frequency_line" && m.kind != "unexplained_line") {
      h.push_back({"unequal current sensor gains", "current_sensor_gain",
                   "show a 2 theta_e pattern in the held DC voltages and a stationary-frame HF component"});
      return h;
    }
  }
  if (m.signal == "rotor_angle") {
    h.push_back({"the angle sensor's own error following the rotor's position (an encoder mounted off the shaft's "
                 "axis, a resolver's once-per-revolution error)",
                 "", "appear at the same mechanical angle at every speed; at standstill, locked points in different "
                 "pole-pair sectors at one electrical angle differ"});
    h.push_back({"speed ripple (a load or coupling that pulses once per revolution, torque ripple)", "",
                 "show in the torque transducer and grow as the speed falls"});
    return h;
  }
  if (m.kind == "electrical_harmonic") {
    const int a = std::abs(k);
    const bool six = (a % 6 == 1 || a % 6 == 5) && a > 1;
    if (six) {
      h.push_back({absl::StrFormat("harmonics of the magnet's flux (slotting, magnet shape): back-EMF at %d x f_e", a),
                   "", "grow with speed at any current, be absent at standstill, appear as 6 theta_e in the rotor frame"});
      h.push_back({"the inverter's dead time or switch drop (its 6k +- 1 harmonics)", "dead_time",
                   "distort the HF response at standstill where a phase current crosses zero, and grow as the current "
                   "falls"});
      h.push_back({"spatial harmonics of the inductance (slot openings)", "spatial_harmonics",
                   "grow with current and show as cos(6 theta_e) in the inductance identified at standstill"});
    } else if (k == -1 || a == 2) {
      h.push_back({"unequal phase impedances or current sensor gains (a negative-sequence fundamental)",
                   "current_sensor_gain", "show a 2 theta_e pattern in the held DC voltages at standstill"});
      h.push_back({"an unequal phase resistance (a bad joint)", "phase_resistance_imbalance",
                   "show the same 2 theta_e DC pattern without a stationary-frame HF component"});
    } else {
      h.push_back({absl::StrFormat("a harmonic %d of the electrical frequency: a magnet or winding asymmetry", k), "",
                   "grow with speed, be absent at standstill"});
    }
    return h;
  }
  if (m.kind == "mechanical_order") {
    // A stator-frame line at k f_mech is most likely the fundamental's
    // sideband (rotor-frame order k - p) or the mechanical order itself:
    // the rotor-frame order the physics has is the smallest of |k - p|,
    // |k|, |k + p|.
    const int r = std::min({std::abs(k - pole_pairs), std::abs(k), std::abs(k + pole_pairs)});
    h.push_back({absl::StrFormat("rotor eccentricity: the air gap varies %d time(s) per mechanical revolution", r),
                 "", "make locked points at one electrical angle in different pole-pair sectors differ, and put "
                 "sidebands at +-f_mech beside the HF response at speed"});
    h.push_back({"the angle sensor's eccentricity (an off-axis encoder)", "",
                 "show as the same order in the recorded angle beyond constant speed"});
    h.push_back({"a load torque pulsing with the shaft (coupling misalignment)", "",
                 "show in the torque transducer at the mechanical frequency"});
    h.push_back({"partial demagnetisation: one magnet weaker than the others (overheating, overcurrent, a chipped "
                 "or missing magnet)",
                 "", "grow with speed as a back-EMF would (sidebands f_e (1 +- k / p)), be absent at standstill"});
    return h;
  }
  if (m.kind == "injection_sideband") {
    const int a = std::abs(k);
    if (a == 4 || a == 6 || a == 8 || a == 12) {
      h.push_back({absl::StrFormat("spatial harmonics of the inductance of order %d", a), "spatial_harmonics",
                   absl::StrFormat("make the inductance identified at standstill vary with the rotor angle as cos(%d theta_e)", a)});
    }
    h.push_back({"an inductance that varies with the rotor angle (saliency harmonics, eccentricity)", "",
                 "vary the HF response at standstill with the rotor angle"});
    h.push_back({"a DC-link ripple or a modulation of the applied voltage", "",
                 "put the same sidebands beside every voltage the inverter applies, at standstill too"});
    return h;
  }
  if (m.kind == "injection_harmonic") {
    h.push_back({"the inverter's dead time or switch drop (odd harmonics of the injection where a phase current "
                 "crosses zero)",
                 "dead_time", "show a current-sign pattern in the held DC voltages"});
    h.push_back({"a saturation knee sharper than the calibration's surfaces (the HF current's harmonics)", "",
                 "grow with the HF excursion and sit at the points nearest the knee"});
    h.push_back({"a current sensor nonlinearity", "", "show in the zero sequence"});
    return h;
  }
  const double f = std::abs(m.frequency_hz);
  if (m.kind == "fixed_frequency_line" || m.kind == "unexplained_line") {
    const bool mains = Near(std::fmod(f + 1.0, 50.0), 1.0, 1.5) || Near(std::fmod(f + 1.0, 60.0), 1.0, 1.5);
    if (mains) {
      h.push_back({absl::StrFormat("interference from the mains at %.0f Hz (a harmonic of 50 or 60 Hz) picked up by "
                                   "the current sensing",
                                   f),
                   "", "keep its frequency and size at every operating point, and show in the zero sequence when one "
                   "sensor picks it up"});
      h.push_back({absl::StrFormat("a DC-link ripple at %.0f Hz (a rectifier's 6 x mains) the modulator does not "
                                   "compensate",
                                   f),
                   "", "put sidebands at +-f beside the injection and the fundamental"});
    }
    h.push_back({absl::StrFormat("interference or a resonance at %.0f Hz (a neighbouring drive, a fan, the "
                                 "bench's mechanics)",
                                 f),
                 "", "keep its frequency when the speed and current change"});
    return h;
  }
  return h;
}

std::vector<H> ForSummarised(const Mismatch& m) {
  std::vector<H> h;
  if (m.kind == "angle_pattern") {
    if (m.signal == "dc_voltage") {
      if (m.order == 1) {
        h.push_back({"current sensor offsets", "current_sensor_offset",
                     "average out of the steady-state rows at speed and leave the HF response alone"});
      } else if (m.order == 2) {
        h.push_back({"unequal current sensor gains", "current_sensor_gain",
                     "also put a stationary-frame component into the HF response"});
        h.push_back({"an unequal phase resistance (a bad joint)", "phase_resistance_imbalance",
                     "leave the HF response alone"});
      }
      h.push_back({"the inverter's dead time (its current-sign pattern follows the current's angle)", "dead_time",
                   "grow as the held current falls and distort the HF response where a phase current crosses zero"});
    } else {
      if (m.order == 2) {
        h.push_back({"an angle sensor error at twice the electrical angle (unequal resolver windings, an "
                     "off-centre encoder disc)",
                     "position_sensor_harmonic", "rotate the HF response's saliency with 2 theta_e, not change its size"});
      }
      if (m.order == 4 || m.order == 6 || m.order == 8 || m.order == 12) {
        h.push_back({absl::StrFormat("spatial harmonics of the inductance of order %d", m.order), "spatial_harmonics",
                     "change the HF response's size, not its phase"});
      }
      h.push_back({"unequal current sensor gains", "current_sensor_gain",
                   "show a 2 theta_e pattern in the held DC voltages as well"});
      h.push_back({"rotor eccentricity or another mechanical-order effect seen at the locked angles", "",
                   "make points at one electrical angle in different pole-pair sectors differ"});
    }
    return h;
  }
  if (m.signal == "hf_current") {
    h.push_back({"the inverter's dead time or switch drop", "dead_time",
                 "show a current-sign pattern in the held DC voltages"});
    h.push_back({"an extra HF resistance (eddy currents)", "hf_resistance",
                 "turn the positive-sequence HF current's phase, not its size"});
    h.push_back({"an extra delay between command and inverter", "sampling_delay",
                 "turn the HF phasors by a phase that grows with frequency and the steady-state voltages by w_e tau"});
  } else if (m.signal == "dc_voltage") {
    h.push_back({"a stator resistance off nominal, or a winding warming during the test", "stator_resistance",
                 "scale every held voltage with the current (or with the recording order for a drift)"});
    h.push_back({"the inverter's dead time or switch drop", "dead_time", "follow the sign of each phase current"});
  } else if (m.signal == "steady_state_voltage" || m.signal == "torque") {
    if (m.signal == "torque") {
      h.push_back({"friction and drag between the air gap and the torque transducer, or the transducer's zero",
                   "torque_loss",
                   "take about the same off every row's torque whatever its current (more at higher speed) and leave "
                   "the voltages alone"});
    }
    h.push_back({"a magnet flux off nominal (magnet temperature)", "magnet_temperature",
                 "change the back-EMF in proportion to speed, and the torque"});
    h.push_back({"an angle offset", "position_offset", "rotate the steady-state voltages and the HF saliency alike"});
    h.push_back({"a DC-link voltage measured with a gain error", "dc_link_sense_gain",
                 "scale every applied voltage while the torque agrees with the currents"});
  }
  return h;
}

}  // namespace

void AttachHypotheses(std::vector<Mismatch>* mismatches, int pole_pairs) {
  for (auto& m : *mismatches) {
    if (!m.hypotheses.empty()) continue;
    const bool waveform = m.signal == "phase_current" || m.signal == "zero_sequence_current" ||
                          m.signal == "rotor_angle" || m.signal == "phase_voltage";
    m.hypotheses = waveform ? ForLine(m, pole_pairs) : ForSummarised(m);
  }
}

}  // namespace fluxcal::diag::detail
