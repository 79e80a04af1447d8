#include "diagnosis/internal.h"

#include <algorithm>
#include <cmath>
#include <functional>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace fluxcal::diag::detail {

// The three phase gains of m1, m2 (g_x = m1 + 2 Re(m2 e^{-j 2 phi_x}), sum of
// the deviations zero) and the zero-sum phase offsets of an alpha-beta
// offset o (o_x = Re(o e^{-j phi_x})).
extern const double kPhasePhi[3];
const double kPhasePhi[3] = {0, 2 * kPi / 3, 4 * kPi / 3};
double PhaseGain(double m1, Complex m2, int x) { return m1 + 2 * std::real(m2 * std::polar(1.0, -2 * kPhasePhi[x])); }
double PhaseOffset(Complex o, int x) { return std::real(o * std::polar(1.0, -kPhasePhi[x])); }

// The finding for an accepted candidate: the catalogue's explanation and
// the block's parameters in the catalogue's names and units.
Finding Describe(const Candidate& c, const Model& m, const FitOut& f) {
  Finding out;
  out.effect = c.effect;
  const sim::EffectRow* row = sim::FindEffect(c.effect);
  if (row != nullptr) out.explanation = std::string(row->explanation);
  auto sd = [&](Block b, int i) { return f.stdev.count(b) ? f.stdev.at(b)[i] : 0.0; };
  // A parameter and its standard deviation, under one name.
  auto set = [&](const std::string& name, double value, double stdev) {
    out.parameters[name] = value;
    out.parameter_std[name] = stdev;
  };
  const auto ptr = f.p.Ptrs();
  const double* const* p = ptr.data();
  switch (c.block) {
    case kDead:
      // Effective dead time acting (declared uncompensated part included).
      set("dead_time_s", m.DeadTime(p), kScaleDead * sd(kDead, 0));
      if (m.ith_estimated) {
        // An extension of docs/diagnosis-report.md's vocabulary: the soft
        // sign's current, profiled (diagnose.cc).
        out.parameters["i_th_a"] = m.ith_a;
        if (m.ith_std_a > 0) out.parameter_std["i_th_a"] = m.ith_std_a;
      }
      if (m.udc_ratio <= kTwoUdcRatio && m.udc_nom_v > 0) {
        // Per phase the error is (Td/Ts) Udc + V_th times the same soft
        // sign: at one Udc the finding's extra Td is a threshold of
        // (Td - Td_nominal) Udc / Ts just as well.
        out.alternatives.push_back(
            {"inverter_voltage_drop",
             {{"threshold_v", (m.DeadTime(p) - m.dead_nom_s) * m.udc_nom_v / m.ts}},
             "the held points share one DC-link voltage, and a switch threshold has the dead time's current-sign "
             "pattern there; points repeated at a second Udc (fluxcal simulate --second-udc-v) separate them: the "
             "dead time's error scales with Udc, the threshold does not"});
      }
      break;
    case kRs:
      set("rs_ohm", m.Rs(p), kScaleRs * sd(kRs, 0));
      if (m.Rs(p) > m.rs_nom) {
        // v_x = (Rs + r_on) i_x + ... in the DC, HF and steady-state
        // responses alike: one device of each leg always carries the phase
        // current.
        out.alternatives.push_back(
            {"inverter_voltage_drop",
             {{"slope_ohm", m.Rs(p) - m.rs_nom}},
             "the switches' on-state slope r_on is in series with the winding in every response seen through the "
             "inverter's commands; a four-wire resistance measured at the motor terminals separates them"});
      }
      break;
    case kAngleHarm: {
      const Complex c = m.AngleHarm(p);
      const double sa = kScaleAngleHarm * std::max(sd(kAngleHarm, 0), sd(kAngleHarm, 1));
      set("harmonic_amplitude_rad", std::abs(c), sa);
      set("harmonic_phase_rad", std::arg(c), std::abs(c) > 0 ? sa / std::abs(c) : kPi);
      break;
    }
    case kIronLoss: {
      // Reported as the resistance; its deviation by the delta method.
      const double g = m.Gfe(p), sg = kScaleGfe * sd(kIronLoss, 0);
      set("r_fe_ohm", g != 0.0 ? 1.0 / g : 0.0, g != 0.0 ? sg / (g * g) : 0.0);
      break;
    }
    case kVth:
      set("threshold_v", m.Vth(p), kScaleVth * sd(kVth, 0));
      if (m.ith_estimated) {   // the same soft sign as the dead time's
        out.parameters["i_th_a"] = m.ith_a;
        if (m.ith_std_a > 0) out.parameter_std["i_th_a"] = m.ith_std_a;
      }
      break;
    case kRhf:
      set("r_hf_ohm", m.RHf(p), kScaleRhf * sd(kRhf, 0));
      break;
    case kOffset:
      set("offset_rad", m.Offset(p), kScaleOffset * sd(kOffset, 0));
      break;
    case kGain: {
      const char* names[3] = {"gain_a", "gain_b", "gain_c"};
      const double sdr = kScaleGain * std::max(sd(kGain, 0), sd(kGain, 1));
      for (int x = 0; x < 3; ++x) {
        out.parameters[names[x]] = PhaseGain(m.M1(p), m.M2(p), x);
        out.parameter_std[names[x]] = std::hypot(2 * sdr, kScaleGain * sd(kGain, 2));
      }
      break;
    }
    case kPsi:
    case kPsiDrift:
      // The mean over the steady-state rows; a drift (docs/diagnosis-report.md)
      // also as psi_pm at the first and the last row in recording order.
      set("psi_pm_wb", m.PsiPm(p), m.psi_nom * kScalePsi * sd(kPsi, 0));
      if (c.block == kPsiDrift) {
        out.parameters["psi_pm_start_wb"] = m.PsiPm(p, 0.0);
        out.parameters["psi_pm_end_wb"] = m.PsiPm(p, 1.0);
        const double sm = kScalePsi * sd(kPsi, 0), sdr = 0.5 * kScalePsi * sd(kPsiDrift, 0);
        out.parameter_std["psi_pm_start_wb"] = m.psi_nom * std::hypot(sm, sdr);
        out.parameter_std["psi_pm_end_wb"] = m.psi_nom * std::hypot(sm, sdr);
      }
      break;
    case kDelay:
      set("delay_s", m.Delay(p), kScaleDelay * sd(kDelay, 0));
      break;
    case kHarm:
      out.parameters["order"] = c.order;
      set("amplitude_h", m.Harm(p), kScaleHarm * sd(kHarm, 0));
      out.explanation = absl::StrFormat("the identified inductance at standstill varies with rotor angle as "
                                        "cos(%d theta_e), beyond the saliency's 2 theta_e", c.order);
      break;
    case kSensorOffset: {
      const char* names[3] = {"offset_a_a", "offset_b_a", "offset_c_a"};
      const double sdo = kScaleSensorOffset * std::max(sd(kSensorOffset, 0), sd(kSensorOffset, 1));
      for (int x = 0; x < 3; ++x) {
        out.parameters[names[x]] = PhaseOffset(m.SensorOffset(p), x);
        out.parameter_std[names[x]] = sdo;
      }
      break;
    }
    case kUdcGain:
      // udc_gain is the contract's name (docs/diagnosis-report.md);
      // udc_sense_gain, the catalogue's, stays beside it (same value).
      set("udc_gain", m.UdcGain(p), kScaleUdcGain * sd(kUdcGain, 0));
      set("udc_sense_gain", m.UdcGain(p), kScaleUdcGain * sd(kUdcGain, 0));
      break;
    case kRImb: {
      // dr_x = 2 Re(r2 e^{-j 2 phi_x}), the zero-sum set (the common part is Rs).
      const char* names[3] = {"dr_a_ohm", "dr_b_ohm", "dr_c_ohm"};
      // The contract's r_x_ohm: each phase's resistance, the model's Rs
      // (the common part) plus its zero-sum share.
      const char* absolute[3] = {"r_a_ohm", "r_b_ohm", "r_c_ohm"};
      const double sdr = kScaleRImb * std::max(sd(kRImb, 0), sd(kRImb, 1));
      for (int x = 0; x < 3; ++x) {
        const double dr = 2 * std::real(m.RImb(p) * std::polar(1.0, -2 * kPhasePhi[x]));
        out.parameters[names[x]] = dr;
        out.parameter_std[names[x]] = 2 * sdr;
        out.parameters[absolute[x]] = m.Rs(p) + dr;
        out.parameter_std[absolute[x]] = std::hypot(2 * sdr, kScaleRs * sd(kRs, 0));
      }
      break;
    }
    case kTorqueLoss: {
      // Reported as friction and drag (physics/torque.h); the block's first
      // parameter is the loss at the rows' mean speed, so the friction's
      // deviation is that of T_ref - b w_ref (covariance neglected: the
      // centring makes the two nearly independent).
      const double sb = kScaleViscous * sd(kTorqueLoss, 1);
      set("friction_nm", m.Friction(p), std::hypot(kScaleFriction * sd(kTorqueLoss, 0), sb * m.torque_ref_rad_s));
      set("viscous_nm_per_rad_s", m.Viscous(p), sb);
      break;
    }
    case kDrift: {
      // A drift is reported as one (docs/diagnosis-report.md): Rs at the
      // first and the last point of the recording, and the rise.
      set("winding_temp_rise_k", kScaleDrift * p[kDrift][0], kScaleDrift * sd(kDrift, 0));
      out.parameters["rs_start_ohm"] = m.RsAt(p, 0.0);
      out.parameters["rs_end_ohm"] = m.RsAt(p, 1.0);
      const double drs = m.Rs(p) * sim::kCopperAlphaPerK * kScaleDrift * sd(kDrift, 0);
      out.parameter_std["rs_end_ohm"] = std::hypot(drs, kScaleRs * sd(kRs, 0));
      out.parameter_std["rs_start_ohm"] = kScaleRs * sd(kRs, 0);
      break;
    }
    default:
      break;
  }
  return out;
}

// Whether every parameter of a candidate's fit lies within its plausible
// range (catalogue's plausible_min) or within 3 standard deviations of it.
bool Plausible(const Candidate& c, const FitOut& f, const Model& m) {
  const Finding d = Describe(c, m, f);
  const sim::EffectRow* row = sim::FindEffect(c.effect);
  if (row == nullptr) return true;
  for (const auto& par : row->parameters) {
    const auto it = d.parameters.find(std::string(par.name));
    if (it == d.parameters.end()) continue;
    const auto sd = d.parameter_std.find(std::string(par.name));
    const double s = sd == d.parameter_std.end() ? 0.0 : sd->second;
    if (it->second < par.plausible_min - 3 * s) return false;
  }
  return true;
}

// Distance of an effect's parameter from neutral, in standard deviations.
double Significance(const Candidate& c, const FitOut& f, const Model& m) {
  // Materiality (the catalogue's floors): below them no calibration
  // decision changes, however precisely the data pin the value down. The
  // size of a finding is its largest parameter's distance from neutral.
  const Finding d = Describe(c, m, f);
  const sim::EffectRow* row = sim::FindEffect(c.effect);
  if (row == nullptr) return 0.0;
  bool material = false;
  for (const auto& par : row->parameters) {
    const auto it = d.parameters.find(std::string(par.name));
    if (it == d.parameters.end() || par.name == "order") continue;
    double size = 0, floor = par.floor;
    if (par.floor_kind == sim::FloorKind::kBelow) {
      // A parallel resistance: material when present (> 0) and small.
      if (it->second > 0 && it->second <= par.floor) material = true;
      continue;
    }
    if (par.floor_kind == sim::FloorKind::kRelativeNominal) {
      const double nominal = par.name == "rs_ohm" ? m.rs_nom : m.psi_nom;
      size = std::abs(it->second - nominal);
      floor = par.floor * std::max(std::abs(nominal), par.name == "rs_ohm" ? 1e-3 : 0.0);
    } else {
      // The reported dead time includes what the manifest declares
      // uncompensated (part of the nominal model); the finding is the rest.
      const double reference = par.name == "dead_time_s" ? m.dead_nom_s : par.neutral;
      size = std::abs(it->second - reference);
    }
    if (size >= floor) material = true;
  }
  if (!material) return 0.0;
  if (!f.stdev.count(c.block)) return 0.0;
  if (!Plausible(c, f, m)) return 0.0;
  double best = 0;
  for (int i = 0; i < kBlockSize[c.block]; ++i) {
    const double sd = f.stdev.at(c.block)[i];
    if (sd > 0) best = std::max(best, std::abs(f.p.b[c.block][i]) / sd);
  }
  return best;
}

}  // namespace fluxcal::diag::detail
