// Diagnosis internals (not a public API): the effect model (parameter
// blocks scaled by the catalogue, observations, predictions), the refit,
// locating, the observations built from a recording, the verdict's pieces,
// the waveform evidence and the corrected fit data. One job per source
// file: effect model (this header), refit.cc, locate.cc, observations.cc,
// verdict.cc, evidence.cc, corrected.cc; Diagnose() in diagnose.cc.
// Unit-tested piece by piece in tests/diagnosis/pieces_test.cc.
#ifndef FLUXCAL_DIAGNOSIS_INTERNAL_H_
#define FLUXCAL_DIAGNOSIS_INTERNAL_H_

#include <cmath>
#include <complex>
#include <map>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "absl/status/statusor.h"
#include "diagnosis/diagnose.h"
#include "fitting/fit.h"
#include "fitting/flux_family.h"
#include "fitting/surface.h"
#include "identification/identify.h"
#include "io/recording_set.h"
#include "simulation/effects.h"
#include "simulation/frames.h"
#include "simulation/twin.h"
#include "physics/delay.h"
#include "physics/hf.h"
#include "physics/inverter.h"
#include "physics/torque.h"

namespace fluxcal::diag::detail {

using Complex = std::complex<double>;
using sim::kPi;
using sim::kSqrt3;
constexpr double kIth = 1.0;    // soft-sign current of the dead-time model [A], before its profile
// Two DC-link voltages differing by more than 10 %: the dead time's error
// (proportional to Udc) and a switch threshold (not) part by at least 10 %
// of their size, several times the held voltages' noise at EOL currents.
constexpr double kTwoUdcRatio = 1.1;


// ---- Parameter blocks (scaled to order one) -----------------------------
// kBase: the flux-linkage surfaces, the parameters of the set's own
// calibration family (fit::Family; Model::BlockSize), element 0 (the
// family's psi_pm slot) held at zero: psi_pm is the nominal value times
// the kPsi block.
enum Block {
  kBase, kDead, kRs, kRhf, kOffset, kGain, kPsi, kDelay, kHarm, kSensorOffset, kUdcGain, kRImb, kDrift,
  kVth, kAngleHarm, kIronLoss, kPsiDrift, kTorqueLoss, kNumBlocks
};
constexpr int kBlockSize[kNumBlocks] = {0, 1, 1, 1, 1, 3, 1, 1, 1, 2, 1, 2, 1, 1, 2, 1, 1, 2};
// Fit scales of the effect blocks, from the catalogue (simulation/effects.h):
// value = neutral + scale x block value (psi_pm relative to its nominal).
const double kScaleDead = sim::EffectParam("dead_time", "dead_time_s").fit_scale;
const double kScaleRs = sim::EffectParam("stator_resistance", "rs_ohm").fit_scale;
const double kScaleRhf = sim::EffectParam("hf_resistance", "r_hf_ohm").fit_scale;
const double kScaleOffset = sim::EffectParam("position_offset", "offset_rad").fit_scale;
const double kScaleGain = sim::EffectParam("current_sensor_gain", "gain_a").fit_scale;
const double kScalePsi = sim::EffectParam("magnet_temperature", "psi_pm_wb").fit_scale;
const double kScaleDelay = sim::EffectParam("sampling_delay", "delay_s").fit_scale;
const double kScaleHarm = sim::EffectParam("spatial_harmonics", "amplitude_h").fit_scale;
const double kScaleSensorOffset = sim::EffectParam("current_sensor_offset", "offset_a_a").fit_scale;
const double kScaleUdcGain = sim::EffectParam("dc_link_sense_gain", "udc_sense_gain").fit_scale;
const double kScaleRImb = sim::EffectParam("phase_resistance_imbalance", "dr_a_ohm").fit_scale;
const double kScaleDrift = sim::EffectParam("stator_temperature_drift", "winding_temp_rise_k").fit_scale;
const double kScaleVth = sim::EffectParam("inverter_voltage_drop", "threshold_v").fit_scale;
// iron_loss is fitted as the conductance 1 / R_fe (linear in the model).
const double kScaleGfe = sim::EffectParam("iron_loss", "r_fe_ohm").fit_scale;
const double kScaleAngleHarm = sim::EffectParam("position_sensor_harmonic", "harmonic_amplitude_rad").fit_scale;
const double kScaleFriction = sim::EffectParam("torque_loss", "friction_nm").fit_scale;
const double kScaleViscous = sim::EffectParam("torque_loss", "viscous_nm_per_rad_s").fit_scale;
struct Candidate {
  std::string effect;
  Block block;
  int order = 0;   // spatial harmonics only
  // A second block freed with it (magnet_temperature drifting: the drift
  // beside the mean); kNumBlocks: none.
  Block also = kNumBlocks;
};

// Per-observation data, precomputed from the recording.
struct HfObs {
  std::string point;
  double id_a, iq_a, w_e, theta, speed_rpm;
  Complex i0, i1, v_eff, dead_hf, dead_neg;
  Complex v_neg_eff;   // the command's negative sequence (ident::HfPointResult::v_neg_eff_v)
  Complex dead_hf_v, dead_neg_v;   // the same per volt of switch threshold (no Udc / Ts factor)
  size_t wave = 0, samples = 0;   // waveform index, samples the demodulator used
  Complex mean_e2;   // window mean of e^{-j 2 theta}: what a stationary-frame
                     // component at -w_i contributes to the I1 projection   // dead-time HF voltage error per second of Td, on the
                                            // positive- and negative-sequence bases
  double sigma0, sigma1, scale;
  bool locked;
  double progress = 0;   // position in the test's order, 0..1 (stator_temperature_drift)
  // Rotating points, per candidate harmonic order n (index in kHarmOrders):
  // window means P = <e^{j((n+1) theta - w_i t)}>, Q = <e^{-j((n-1) theta + w_i t)}>
  // that project the harmonic's fundamental-current voltage on the
  // demodulators' bases (Model::PredictHf).
  Complex harm_p[4], harm_q[4];
};
constexpr int kHarmOrders[4] = {4, 6, 8, 12};
inline int HarmIndex(int order) {
  for (int k = 0; k < 4; ++k) if (kHarmOrders[k] == order) return k;
  return -1;
}
struct DcObs {
  std::string point;
  double id_a, iq_a, theta;
  double progress = 0;
  size_t wave = 0, samples = 0;     // waveform index, samples averaged
  Complex u, dead;                  // dead: command change per second of dead time
  Complex dead_v;                   // the same per volt of switch threshold
  double udc_v = 0;                 // mean recorded DC-link voltage of the point
  bool second_udc = false;          // recorded at the set's second DC-link voltage
  double sigma;
};
struct SsObs {
  double id_a, iq_a, speed_rpm, w_e;
  double progress = 0.5;   // the row's place among the steady-state rows in recording order, 0..1
  Complex u, dead, dead_v;
  double sigma, scale;
  bool has_torque;
  double torque, torque_sigma;
};

struct Model {
  int pole_pairs = 4;
  double rs_nom = 0.01, psi_nom = 0.01, w_i = 2 * kPi * 500, ts = 1e-4;
  // Dead time the manifest declares uncompensated (0 when compensated): part
  // of the nominal drive; the dead_time effect is what acts beyond it.
  double dead_nom_s = 0.0;
  // Soft-sign current of the dead-time and threshold errors, tanh(i / i_th)
  // per phase (SetSoftSignCurrent).
  double ith_a = kIth;
  bool ith_estimated = false;   // profiled by Diagnose (else kIth assumed)
  double ith_std_a = 0.0;
  std::vector<HfObs> hf;
  std::vector<DcObs> dc;
  std::vector<SsObs> ss;
  int harm_order = 6;
  double dc_scale_v = 0.1, torque_scale_nm = 0.1;   // RelativeRms
  // Highest over lowest mean DC-link voltage of the held (locked) points:
  // above kTwoUdcRatio the dead time and a switch threshold are separable.
  double udc_ratio = 1.0;
  double udc_nom_v = 0.0;   // the manifest's drive.udc_v
  // The torque rows' mean mechanical speed |w_m| [rad/s]: the torque_loss
  // block is (loss at this speed, drag), centred so that its two
  // parameters are not collinear over a test's speeds.
  double torque_ref_rad_s = 0.0;
  // The set's scales of the catalogue's materiality floors
  // (sim::FloorScale, observations.cc): the largest current magnitude it
  // commands [A], the largest |torque| its rows record [N m], its mean
  // identified HF inductance (Ld + Lq) / 2 [H], and its Rs and Udc: the
  // manifest's, or where the manifest leaves them out (both optional in
  // docs/recording-format.md) the median held |u| / |i| of its standstill
  // points and their mean recorded DC-link voltage, so that a missing value
  // never makes every effect material.
  double scale_current_a = 0.0, scale_torque_nm = 0.0, scale_inductance_h = 0.0;
  double scale_rs_ohm = 0.0, scale_udc_v = 0.0;
  double FloorScaleValue(sim::FloorScale s) const {
    switch (s) {
      case sim::FloorScale::kNone: return 1.0;
      case sim::FloorScale::kRsNominal: return scale_rs_ohm;
      case sim::FloorScale::kCurrentMax: return scale_current_a;
      case sim::FloorScale::kUdc: return scale_udc_v;
      case sim::FloorScale::kTorqueMax: return scale_torque_nm;
      case sim::FloorScale::kInductance: return scale_inductance_h;
      case sim::FloorScale::kReactance: return w_i * scale_inductance_h;
    }
    return 1.0;
  }

  // The magnetics: the set's own calibration (fit::Fit of its identified
  // points and steady-state rows, the fit `fluxcal fit SET` makes), its
  // family and parameters refitted beside the effects, with the smoothing
  // spline's roughness penalty at the calibration's own weight (refit.cc).
  // A machine's saturation and cross saturation are its calibration, never
  // missing physics (docs/diagnosis.md, "The baseline").
  fit::Family surf;
  std::vector<double> surf_init;        // the calibration's parameters, psi_pm slot 0
  // The roughness penalty lambda |R c|^2, R^T R = P^T P (+ eps I) of the
  // smoothing spline (fit.cc); 0 rows: a family without one. lambda is the
  // calibration's; each refit chooses its own (refit.cc, Solve).
  Eigen::MatrixXd surf_R;
  double surf_lambda = 0;
  // The least weight a refit may choose (Solve). A candidate effect's
  // refit keeps its surfaces at least as smooth as the current model's:
  // an effect explains what the surfaces had to bend for, so with it they
  // are smoother (diagnose.cc, RelaxesSurfaces), never rougher. A candidate
  // whose criterion prefers rougher surfaces is trading its parameter
  // against their flexibility, and with the noise scale estimated from the
  // data (refit.cc, Bic) n ln RSS rewards interpolation without bound once
  // the effect has removed what the surfaces could not follow: a strongly
  // cross-saturated machine's 0.03 rad angle offset refitted at 1e-4 of the
  // current weight, 89 effective parameters of 198 at chi^2 0.4, and the
  // offset 2.6 sigma, unnamed; at the current weight chi^2 151 -> 20 with
  // 41 (docs/diagnosis.md, "A candidate's surfaces are never rougher").
  double surf_lambda_floor = 0;
  double surf_anisotropy_q = 1;   // the calibration's SmoothingPenalty kappa
  double surf_curvature_weight = 0;   // and its curvature weight mu
  double surf_k_eff = 0;                // effective parameters of the surfaces (BIC)
  int BlockSize(int b) const { return b == kBase ? surf.NumParams() : kBlockSize[b]; }
  // psi_pm at the kPsi block (magnet_temperature), relative to nominal;
  // with `progress` (0..1, a steady-state row's place in recording order)
  // also the drift of the kPsiDrift block: its change from the first row to
  // the last, the mean kept at kPsi.
  double PsiPm(const double* const* p, double progress = -1.0) const {
    const double drift = progress >= 0.0 ? p[kPsiDrift][0] * (progress - 0.5) : 0.0;
    return psi_nom * (1 + kScalePsi * (p[kPsi][0] + drift));
  }

  // A probe of the surfaces for the chain rule (refit.cc): while `on`, every
  // surface value read is shifted by `delta` (psi_d, psi_q, Ldd, Lqq, Ldq)
  // and the last operating point read is recorded. Single-threaded use only.
  struct SurfaceProbe {
    bool on = false, seen = false;
    double delta[fit::kSurfaceValues] = {};
    double id_a = 0, iq_a = 0;
  };
  mutable SurfaceProbe probe;

  // Differential inductance of the surfaces (flux_family.h, the Hessian of
  // the co-energy).
  void Inductance(const double* const* p, double id, double iq, double* ldd, double* lqq, double* ldq) const {
    fit::FamilyInductance(surf, id, iq, p[kBase], ldd, lqq, ldq);
    if (probe.on) {
      *ldd += probe.delta[fit::kLdd];
      *lqq += probe.delta[fit::kLqq];
      *ldq += probe.delta[fit::kLdq];
      probe.seen = true;
      probe.id_a = id;
      probe.iq_a = iq;
    }
  }
  // Flux linkage: gradient of the same co-energy (psi = grad W'), with the
  // magnet flux of the kPsi block.
  void Flux(const double* const* p, double id, double iq, double* pd, double* pq, double progress = -1.0) const {
    fit::FamilyFlux(surf, id, iq, p[kBase], pd, pq);
    *pd += PsiPm(p, progress) - p[kBase][0];
    if (probe.on) {
      *pd += probe.delta[fit::kPsiD];
      *pq += probe.delta[fit::kPsiQ];
      probe.seen = true;
      probe.id_a = id;
      probe.iq_a = iq;
    }
  }
  double Rs(const double* const* p) const { return rs_nom + kScaleRs * p[kRs][0]; }
  double DeadTime(const double* const* p) const { return dead_nom_s + kScaleDead * p[kDead][0]; }
  // inverter_voltage_drop: the switches' threshold V_th (its slope r_on is
  // in series with Rs and lives in Rs(p); docs/diagnosis.md).
  double Vth(const double* const* p) const { return kScaleVth * p[kVth][0]; }
  // torque_loss: friction T_f and drag b of T_loss = sign(n) (T_f + b |w_m|)
  // (physics/torque.h), from the block (T at the reference speed, b).
  double Viscous(const double* const* p) const { return kScaleViscous * p[kTorqueLoss][1]; }
  double Friction(const double* const* p) const {
    return kScaleFriction * p[kTorqueLoss][0] - Viscous(p) * torque_ref_rad_s;
  }
  // iron_loss: conductance of the branch parallel to the magnetising one.
  double Gfe(const double* const* p) const { return kScaleGfe * p[kIronLoss][0]; }
  // Steady state with iron loss: the branch voltage e = w_e J psi(i_m) drives
  // g e beside the magnetising current, so i_m = i - g w_e J psi(i_m), solved
  // by two fixed-point steps (g w_e L ~ 1e-2: each step gains two digits).
  Complex MagnetisingCurrent(const double* const* p, Complex i, double w_e, double progress = -1.0) const {
    const double g = Gfe(p);
    if (g == 0.0 || w_e == 0.0) return i;
    Complex im = i;
    for (int it = 0; it < 2; ++it) {
      double pd, pq;
      Flux(p, im.real(), im.imag(), &pd, &pq, progress);
      im = i - g * w_e * Complex(-pq, pd);
    }
    return im;
  }
  // position_sensor_harmonic as c = amplitude e^{j phase}: the reading's
  // error a sin(2 theta + phase) = Im(c e^{j 2 theta}), linear in the block.
  Complex AngleHarm(const double* const* p) const {
    return kScaleAngleHarm * Complex(p[kAngleHarm][0], p[kAngleHarm][1]);
  }
  // The angle sensor's error at a point: the offset, plus at standstill the
  // harmonic at the locked angle (at speed it swings at 2 w_e and averages
  // out of the demodulated phasors to first order). The true angle is the
  // reading less the offset, to first order in the harmonic.
  double AngleError(const double* const* p, bool locked, double theta_meas) const {
    if (!locked) return Offset(p);
    return Offset(p) + std::imag(AngleHarm(p) * std::polar(1.0, 2 * (theta_meas - Offset(p))));
  }
  double Offset(const double* const* p) const { return kScaleOffset * p[kOffset][0]; }
  double Delay(const double* const* p) const { return kScaleDelay * p[kDelay][0]; }
  double RHf(const double* const* p) const { return kScaleRhf * p[kRhf][0]; }
  double Harm(const double* const* p) const { return kScaleHarm * p[kHarm][0]; }
  Complex M2(const double* const* p) const { return kScaleGain * Complex(p[kGain][0], p[kGain][1]); }
  // Mean sensor gain m1 (measured = m1 i + m2 conj(i) in alpha-beta).
  double M1(const double* const* p) const { return 1.0 + kScaleGain * p[kGain][2]; }
  // current_sensor_offset in alpha-beta (the zero sequence of three phase
  // offsets cancels in the Clarke transform of a star winding: unobservable).
  Complex SensorOffset(const double* const* p) const {
    return kScaleSensorOffset * Complex(p[kSensorOffset][0], p[kSensorOffset][1]);
  }
  // dc_link_sense_gain: measured / true Udc; the modulator applies
  // command / gain, so every command is gain x the voltage the machine needs.
  double UdcGain(const double* const* p) const { return 1.0 + kScaleUdcGain * p[kUdcGain][0]; }
  // phase_resistance_imbalance: per-phase drops dr_x i_x are, in
  // alpha-beta, mean(dr) i + r2 conj(i) with r2 = (1/3) sum dr_x e^{j 2 phi_x};
  // mean(dr) is stator_resistance, r2 is this block.
  Complex RImb(const double* const* p) const { return kScaleRImb * Complex(p[kRImb][0], p[kRImb][1]); }
  // stator_temperature_drift: Rs at a point recorded a fraction `progress`
  // of the way through the locked/rotating points (1 for steady state).
  double RsAt(const double* const* p, double progress) const {
    return Rs(p) * (1.0 + sim::kCopperAlphaPerK * kScaleDrift * p[kDrift][0] * progress);
  }

  // Eqs. (E1)-(E2) of identification/inductance.h with a voltage on both
  // sequences and the magnetising branch with iron loss (physics/hf.h).
  void SolvePhasors(double ldd, double lqq, double ldq, double r, Complex v, Complex vn, double w_e,
                    Complex* i0, Complex* i1, double g_fe = 0.0) const {
    physics::SolveHfPhasors(ldd, lqq, ldq, r, v, vn, w_i, w_e, g_fe, i0, i1);
  }
  // What an extra delay tau of the held (staircase) command does to the
  // phasor of the *sampled* HF current (physics/delay.h): not the pure
  // e^{-j w tau}; at half a sample the magnitude is cos(w T / 2) (-1.2 % at
  // 500 Hz, 10 kHz), which would otherwise be fitted as a 1 % larger inductance.
  Complex StaircaseDelay(double w, double tau_s) const { return physics::StaircaseDelay(w, tau_s, ts); }
  // The operating point of an HF observation in the true rotor frame. The
  // controller held the *measured* current, so at standstill unequal
  // sensor gains put the machine elsewhere by a pattern in twice the rotor
  // angle (TrueCurrent's m2 term; at speed it averages out of the window).
  // On a machine whose inductance falls steeply with its current, a 2 %
  // gain on one phase moves a 26 A point by 0.17 A, and the identified
  // inductance follows: read at the measured current, that pattern was fitted as a
  // spatial harmonic beside the gain (tests/diagnosis/
  // measured_magnetics_test.cc). The mean gain m1 is left out, as in the
  // phasors: it rescales every current alike, which the surfaces absorb.
  // So is a sensor offset's shift (0.07 A for a 0.1 A offset on one phase):
  // with it the same test named a spatial harmonic beside the offset.
  Complex OperatingPoint(const double* const* p, const HfObs& o) const {
    const Complex rot = std::polar(1.0, AngleError(p, o.locked, o.theta));
    const Complex i(o.id_a, o.iq_a);
    return rot * (o.locked ? i - M2(p) * std::polar(1.0, -2 * o.theta) * std::conj(i) : i);
  }
  void PredictHf(const double* const* p, const HfObs& o, Complex* i0, Complex* i1) const {
    const Complex rot = std::polar(1.0, AngleError(p, o.locked, o.theta));
    const Complex it = OperatingPoint(p, o);   // true-frame current
    double ldd, lqq, ldq;
    Inductance(p, it.real(), it.imag(), &ldd, &lqq, &ldq);
    if (o.locked && p[kHarm][0] != 0.0) {
      const double h = Harm(p) * std::cos(harm_order * (o.theta - Offset(p)));
      ldd += h;
      lqq += h;
    }
    const double r = RsAt(p, o.progress) + RHf(p);
    // Applied HF voltage: extra delay rotates it; an uncompensated dead time
    // subtracts its HF component (computed from the recorded currents).
    // A DC-link sense gain scales the applied injection by 1 / gain.
    Complex v = o.v_eff * StaircaseDelay(w_i, Delay(p)) / UdcGain(p) - DeadTime(p) * o.dead_hf - Vth(p) * o.dead_hf_v;
    Complex vn = o.v_neg_eff * StaircaseDelay(2 * o.w_e - w_i, Delay(p)) / UdcGain(p) - DeadTime(p) * o.dead_neg -
                 Vth(p) * o.dead_neg_v;
    const int hk = HarmIndex(harm_order);
    if (!o.locked && p[kHarm][0] != 0.0 && hk >= 0) {
      // At speed the angle-dependent flux h cos(n theta) i of the fundamental
      // current, (h I/2)(e^{j(n+1)theta} + e^{-j(n-1)theta}) with I the dq
      // current, induces d/dt of it: voltages at (n+1) w_e and -(n-1) w_e.
      // Where one falls on the injection (w_i) or the negative sequence
      // (2 w_e - w_i) -- e.g. order 4 at 1500 rpm with 4 pole pairs and
      // 500 Hz: 5 w_e = w_i -- it drives HF current like the injection does.
      // Its share on each basis is the window mean P or Q (docs/diagnosis.md).
      const double h = Harm(p);
      const int n = harm_order;
      const Complex j(0.0, 1.0);
      const Complex half = 0.5 * h * it;
      const Complex up = j * double(n + 1) * o.w_e * half, down = -j * double(n - 1) * o.w_e * half;
      v -= up * o.harm_p[hk] + down * o.harm_q[hk];
      vn -= up * std::conj(o.harm_q[hk]) + down * std::conj(o.harm_p[hk]);
    }
    SolvePhasors(ldd, lqq, ldq, r, v, vn, o.w_e, i0, i1, Gfe(p));
    // The measured angle is true + offset: the negative sequence appears
    // rotated by -2 offset in the measured frame.
    *i1 *= std::conj(rot * rot);
    // Unequal sensor gains: i_meas = i + m2 conj(i) (m1 = 1 absorbed in L).
    const Complex m2 = M2(p);
    const double m1 = M1(p);
    if (m2 != 0.0 || m1 != 1.0) {
      const Complex e2 = o.mean_e2;
      const Complex a0 = *i0, a1 = *i1;
      *i0 = m1 * a0 + m2 * std::conj(a1) * e2;
      *i1 = m1 * a1 + m2 * std::conj(a0) * e2;
    }
  }
  // The controller holds the *measured* current; with unequal sensor gains
  // i_s,meas = i_s + m2 conj(i_s), so in dq the true current is
  // i = i_meas - m2 e^{-j 2 theta} conj(i_meas) to first order.
  // A sensor offset o (alpha-beta) adds o e^{-j theta} to the measured dq
  // current at standstill.
  Complex TrueCurrent(const double* const* p, Complex i_meas, double theta) const {
    const Complex i = i_meas - SensorOffset(p) * std::polar(1.0, -theta);
    return (i - M2(p) * std::polar(1.0, -2 * theta) * std::conj(i)) / M1(p);
  }
  Complex PredictDc(const double* const* p, const DcObs& o) const {
    // Holding a DC current at standstill needs u = Rs i (the rotation by an
    // angle offset cancels), plus what counteracts the dead time.
    const Complex it = TrueCurrent(p, Complex(o.id_a, o.iq_a), o.theta);
    // Unequal phase resistances add r2 e^{-j 2 theta} conj(i) in dq.
    const Complex imb = RImb(p) * std::polar(1.0, -2 * o.theta) * std::conj(it);
    return UdcGain(p) * (RsAt(p, o.progress) * it + imb + DeadTime(p) * o.dead + Vth(p) * o.dead_v);
  }
  // The flux at speed behind a measured mean current. With spatial
  // harmonics the inductance swings as L + h cos(n theta) while the flux
  // stays nearly constant (the controller's voltage is smooth at n w_e), so
  // the current swings as psi_i / (L + h cos n theta) and its mean is
  // (psi_i / L)(1 + h^2 / (2 L^2)): the current-dependent flux behind a mean
  // current i is L i (1 - h^2 / (2 L^2)) per axis, to second order in h / L
  // (a 20 uH harmonic on 150 uH moves it 0.9 %).
  void SteadyFlux(const double* const* p, Complex im, double* pd, double* pq, double progress = -1.0) const {
    Flux(p, im.real(), im.imag(), pd, pq, progress);
    if (p[kHarm][0] == 0.0) return;
    const double h = Harm(p);
    double ldd, lqq, ldq;
    Inductance(p, im.real(), im.imag(), &ldd, &lqq, &ldq);
    const double p0d = PsiPm(p, progress);   // psi(0, 0) = (psi_pm, 0) in every family
    if (ldd > 0) *pd = p0d + (*pd - p0d) * (1.0 - 0.5 * h * h / (ldd * ldd));
    if (lqq > 0) *pq *= 1.0 - 0.5 * h * h / (lqq * lqq);
  }
  Complex PredictSs(const double* const* p, const SsObs& o) const {
    const Complex rot = std::polar(1.0, Offset(p));
    const Complex it = rot * Complex(o.id_a, o.iq_a) / M1(p);
    const Complex im = MagnetisingCurrent(p, it, o.w_e, o.progress);
    double pd, pq;
    SteadyFlux(p, im, &pd, &pq, o.progress);
    const double rs = RsAt(p, 1.0);   // recorded after the points: the winding is warm
    const Complex u_true(rs * it.real() - o.w_e * pq, rs * it.imag() + o.w_e * pd);
    return UdcGain(p) * (std::conj(rot) * u_true * std::polar(1.0, o.w_e * Delay(p)) + DeadTime(p) * o.dead +
                         Vth(p) * o.dead_v);
  }
  double PredictTorque(const double* const* p, const SsObs& o) const {
    const Complex it = std::polar(1.0, Offset(p)) * Complex(o.id_a, o.iq_a) / M1(p);
    // Only the magnetising current makes torque (the iron-loss current none).
    const Complex im = MagnetisingCurrent(p, it, o.w_e, o.progress);
    double pd, pq;
    SteadyFlux(p, im, &pd, &pq, o.progress);
    // The transducer reads it less the mechanical loss (torque_loss).
    return physics::ElectromagneticTorque(pole_pairs, pd, pq, im.real(), im.imag()) -
           physics::MechanicalLossTorque(Friction(p), Viscous(p), o.speed_rpm);
  }
};


struct Params {
  std::vector<std::vector<double>> b;
  Params() = default;
  // Every block at zero (neutral), the surfaces at the model's calibration.
  explicit Params(const Model& m) {
    for (int k = 0; k < kNumBlocks; ++k) b.emplace_back(m.BlockSize(k), 0.0);
    b[kBase] = m.surf_init;
  }
  std::vector<const double*> Ptrs() const {
    std::vector<const double*> v;
    for (const auto& x : b) v.push_back(x.data());
    return v;
  }
};

struct FitOut {
  Params p;
  double chi2 = 0, bic = 0, rms = 0;
  double penalty = 0;   // the surfaces' roughness penalty at the solution
  double lambda = 0;    // the penalty weight the fit chose (Solve)
  double k_eff = 0;     // effective parameters (surfaces and effects)
  double Objective() const { return chi2 + penalty; }
  int k = 0, n = 0;
  std::map<Block, std::vector<double>> stdev;
  bool ok = false;
};


// ---- refit.cc ---------------------------------------------------------------
// Observation kinds, as the cost functors number them.
// kDcSecondUdcKind is a region of kDcKind, not a residual kind: the held DC
// voltages of the points recorded at the second DC-link voltage, held out
// as a whole (Solve) to test an explanation of the inverter's voltage error.
enum Kind { kHfKind = 0, kDcKind = 1, kSsKind = 2, kTorqueKind = 3, kDcSecondUdcKind = 4 };
const char* KindSignal(int kind);
// Relative residual RMS over every observable / of one kind (dimensionless).
double RelativeRms(const Model& m, const Params& p);
double RelativeRmsOf(const Model& m, const Params& p, int kind);
// Least squares over every observation except those of kind `held_out`
// (-1: none), with the blocks in `free_blocks` free; covariance of the
// effect blocks.
// choose_lambda: the surfaces' smoothing weight chosen by BIC at the
// solution (refit.cc); false keeps m.surf_lambda.
FitOut Solve(const Model& m, const Params& start, const std::vector<Block>& free_blocks, int held_out = -1,
             bool choose_lambda = true);

// ---- parallel.cc ------------------------------------------------------------
// Independent refits (the candidates of one selection round, the soft-sign
// profile's grid, the held-out classes) run on fit::ParallelFor's threads.
// Each worker has its own copy of the model: a Model carries per-evaluation
// state (the surface probe of ObservationCost, the harmonic order a
// candidate sets). task(k, model) writes only its own output k, so results
// do not depend on the schedule.
// `cancelled` (may be empty) is polled on the calling thread before each
// task it takes; true when it stopped them (some outputs then unset).
bool ParallelForModels(size_t n, const Model& m, const std::function<void(size_t, Model&)>& task,
                       const std::function<bool()>& cancelled = {});

// ---- locate.cc --------------------------------------------------------------
struct Z {
  std::string point, signal;
  double id_a, iq_a, speed_rpm, z2;
  int dof;
  // The signed normalised components behind z2 and the rotor angle of a
  // standstill point (for the angle patterns of AnglePatterns).
  std::vector<double> r;
  double theta = 0;
};
std::vector<Z> Residuals(const Model& m, const Params& p);
struct RegionStat {
  std::string signal, where;
  double chi2 = 0;
  int k = 0;
  std::vector<std::pair<double, std::string>> points;   // (z^2 per dof, point)
  // Gaussian significance of the excess, (chi2 - k) / sqrt(2k).
  double Sigma() const { return k ? (chi2 - k) / std::sqrt(2.0 * k) : 0.0; }
};
std::vector<RegionStat> RegionStats(const std::vector<Z>& zs);
// Standstill residuals that vary with the rotor angle as cos(k theta + phi)
// (k = 1, 2, 3, 4, 6): per signal and order, the chi^2 the pattern explains
// beyond a constant, as a significance; those reaching `threshold`.
std::vector<Mismatch> AnglePatterns(const std::vector<Z>& zs, double threshold);
std::vector<Mismatch> Locate(const std::vector<Z>& zs, double threshold);
bool PracticallySignificant(const std::vector<Z>& before, const std::vector<Z>& after, double rms_before,
                            double rms_after, const DiagnoseOptions& opt);

// ---- observations.cc --------------------------------------------------------
Complex DeadTimeUnit(double ia, double ib, double ic, double udc, double ts, double ith_a = kIth);
// Mean of tanh(i / i_th) over a PWM period in which the current moves
// linearly from i0 to i1 (physics/inverter.h). The HF ripple moves a phase
// current by ~2 A within one period, as much as the soft-sign width, so the
// start-of-period sample is not enough.
inline double MeanSoftSign(double i0, double i1, double ith_a = kIth) { return physics::MeanSoftSign(i0, i1, ith_a); }
absl::StatusOr<Model> BuildModel(const io::RecordingSet& set, std::vector<ident::HfPointResult>* ids);
// (Re)computes every observation's dead-time and switch-threshold
// signatures (dead*, dead_*_v) with the soft sign tanh(i / ith_a) and sets
// m->ith_a: the soft-sign current is a profile parameter of the model
// (Diagnose), not linear in it like Td.
void SetSoftSignCurrent(const io::RecordingSet& set, double ith_a, Model* m);
// The set's own calibration as the model's magnetics (Model::surf*):
// fit::Fit of the identified points and steady-state rows.
void SetSurfaces(const fit::Calibration& cal, Model* m);
absl::Status InitSurfaces(const io::RecordingSet& set, const std::vector<ident::HfPointResult>& ids, Model* m);

// ---- verdict.cc -------------------------------------------------------------
extern const double kPhasePhi[3];
double PhaseGain(double m1, Complex m2, int x);
double PhaseOffset(Complex o, int x);
Finding Describe(const Candidate& c, const Model& m, const FitOut& f);
bool Plausible(const Candidate& c, const FitOut& f, const Model& m);
double Significance(const Candidate& c, const FitOut& f, const Model& m);
// Held-out checks (verdict.cc): the largest move of an effect parameter of
// `free` refitted without a class (`held`) from the full fit's, in
// standard deviations of the difference (Hausman), and whether every
// effect of `free` is found (parameter_sigma from neutral) without it.
double ParameterShiftSigma(const FitOut& held, const FitOut& full, const std::vector<Block>& free);
bool FoundWithout(const FitOut& held, const std::vector<Block>& free, double parameter_sigma);
// Whether some finding's catalogue parameter differs between the fits a
// and b by its materiality floor or more (verdict.cc, FloorValue).
bool MaterialMove(const std::vector<Candidate>& findings, const Model& m, const FitOut& a, const FitOut& b);

// ---- evidence.cc ------------------------------------------------------------
// The currents a set measured: zero and every held point's and
// steady-state row's (A; |iq| up to iq_hi_a).
struct MeasuredBox {
  double id_lo_a = 0, id_hi_a = 0, iq_hi_a = 0;
};
MeasuredBox MeasuredBoxOf(const Model& m);
// The surfaces at (id, iq) for the replays (the family's psi_pm slot
// excluded, as eval's parameters have it): inside the box as fitted, beyond
// it continued at the nearest measured current x0 with its inductance,
// psi(x) = psi(x0) + L(x0) (x - x0) -- the co-energy's second-order Taylor
// polynomial there, the spline family's own continuation
// (fitting/flux_family.h, EvalBasis), continuous in flux and inductance at
// the edge. The injection's current ellipse (+-16 A on the trait machines)
// reaches past the edge points, and a polynomial family fitted inside
// continues to fold there: Ldd negative 20 A beyond the largest measured
// |id| of a surface-magnet machine, where the replay's Newton step jumped to
// the map's other branch (150 A within three samples) and the replay of
// every edge point said nothing of the recording.
void ContinuedSurface(const fit::SurfaceEvaluator& eval, const MeasuredBox& box, double id, double iq, double* pd,
                      double* pq, double* ldd, double* lqq, double* ldq);
// Every waveform point replayed open loop through the twin with the
// model's surfaces and the effects of `p` (sim::ReplayOpenLoop).
absl::StatusOr<std::vector<sim::ReplayPoint>> ReplayModel(const io::RecordingSet& set, const Model& m,
                                                          const Params& p, int harm_order);
// The overall RMS of simulated minus recorded phase currents of a replay,
// and the residual's spectrum at `freqs` (mean over points of |DFT| of the
// complex alpha-beta residual, in A).
// A replay that ran away (a model whose surfaces are not positive definite
// where the recorded voltages drive it, integrated open loop) says nothing
// about the recording: its currents non-finite or above ten times the
// recorded peak. Such a point is left out of the spectra and the locator.
bool ReplayRanAway(const io::Waveform& w, const sim::ReplayPoint& r);
// A point the identification reports failed is one the bench did not hold
// (no HF response left to invert: the controller at the voltage limit, the
// current far from its reference); its waveform says what the bench did,
// not what the machine is, and no model of the machine reproduces it. Its
// replay is emptied here, and the spectra and the locator skip it
// (ReplaySpectrum, AnalyseWaveforms): the identification already reports
// the point. (A bench losing 13 of 40 points of a machine with strong cross
// saturation put 600 A replay residuals and "unexplained" lines at three of
// them into a clean recording's diagnosis.)
void LeaveOutUnheldPoints(const std::vector<ident::HfPointResult>& ids, std::vector<sim::ReplayPoint>* replay);
double ReplaySpectrum(const io::RecordingSet& set, const std::vector<sim::ReplayPoint>& replay,
                      const std::vector<double>& freqs, std::vector<double>* spectrum);

// ---- waveform.cc ------------------------------------------------------------
struct WaveformLine {
  std::string channel;   // phase_current | zero_sequence_current | rotor_angle
  double freq_hz = 0, amp_a = 0, z2 = 0;
  double sim_amp_a = 0;  // the model's own line in the simulated current at that bin
  std::string kind;      // what it is a multiple of ("" : nothing)
  int order = 0, m = 0;
};
struct WaveformPoint {
  std::string point;
  size_t index = 0;                 // recording order
  double id_a = 0, iq_a = 0, speed_rpm = 0, f_e_hz = 0, df_hz = 0;
  double noise_a = 0;               // per-sample noise of the residual (recording's own)
  // The recorded currents' quantisation step (waveform.cc, CurrentStepA), A,
  // and the power its mean error puts in each bin of the residual's
  // spectra (alpha-beta, zero sequence; empty without a step): the
  // sensors' resolution, a bin's noise beside the white floor.
  double current_step_a = 0;
  std::vector<double> quant2, quant2_zero;
  double sigma2_bin = 0, sigma2_bin_zero = 0, coherent_gain = 1;
  std::vector<double> freq_hz, nuisance_hz;
  std::vector<double> angle_nuisance_hz;          // the angle channel's: count-slip sawtooth harmonics
  std::vector<Complex> spectrum, spectrum_zero;   // Hann-windowed residual spectra
  std::vector<Complex> spectrum_sim;              // ... and the simulated current's
  std::vector<Complex> spectrum_angle;            // rotating: the recorded angle less its line
  std::vector<Complex> spectrum_angle_model;      // ... and its count quantisation's
  double sigma2_bin_angle = 0;
  std::vector<WaveformLine> lines;
};
// How far the model's own lines are trusted: where the replay itself
// generates a line (a dead time's 6k +- 1 harmonics and the HF response's
// sidebands at speed, the saturation's harmonics), its size depends on
// details beyond the effect's parameters -- the soft sign's shape, the
// PWM period's timing, the curvature of the magnetics over the HF ellipse
// -- and is taken as uncertain by its own size: a bin's noise is
// sigma^2 + |S|^2, S the simulated current's bin. A residual line is then
// located where it is above the noise and larger than anything the model
// puts there: physics the model has no term for. (A dead time with a
// 0.2 A soft sign on a measured PM-SyRM, replayed with its fitted value,
// leaves 30-100 % of its own 2-30 mA sidebands at 150-300 rpm; kept at
// 5 %, every one of them was a "mismatch".)
constexpr double kModelLineAccuracy = 1.0;
// The size a residual line at bin b must exceed to be more than the
// model's own line there (sim: the simulated current's spectrum;
// waveform.cc).
double ModelLineSize(const std::vector<Complex>& sim, size_t b);
// The residual of every replayed point freed of the nuisance lines, its
// spectra, noise and lines (waveform.cc's comment).
std::vector<WaveformPoint> AnalyseWaveforms(const io::RecordingSet& set, const std::vector<sim::ReplayPoint>& replay,
                                            int pole_pairs);
// ---- quantisation.cc ------------------------------------------------------------
// The sensors' resolution (file comment): the recorded phase currents'
// quantisation step, A (0: none found).
double CurrentStepA(const io::Waveform& w);
// Fills wp->current_step_a, quant2 and quant2_zero: the power the
// quantiser's mean error puts in each bin of the residual's spectra of
// length win.size() (samples 1..n, window `win`), from the simulated
// currents of `r` and wp->noise_a. Empty when the noise dithers it.
void QuantisationSpectra(const io::Waveform& w, const sim::ReplayPoint& r, const std::vector<double>& win,
                         WaveformPoint* wp);
// That power at bin b of a channel ("phase_current", "zero_sequence_current";
// 0 for any other).
double QuantisationPower(const WaveformPoint& wp, const std::string& channel, size_t b);

// ---- mechanical_orders.cc -----------------------------------------------------
// Mechanical-order lines at a rotating point, f_e (1 + o / p), o = +-1,
// in the recorded voltage command (file comment): each at z^2 >= line_z2
// on channel "phase_voltage", its size in V (WaveformLine::amp_a).
std::vector<WaveformLine> MechanicalOrderVoltageLines(const io::Waveform& w, double f_sample_hz, double f_i_hz,
                                                      int pole_pairs, double f_e_hz, double line_z2);

// ---- hypotheses.cc ------------------------------------------------------------
// Fills each mismatch's ranked hypotheses (catalogue effects and physics
// outside it) from its kind, signal and order.
void AttachHypotheses(std::vector<Mismatch>* mismatches, int pole_pairs);

// The lines grouped by what they are multiples of, each group with its
// significance over the points, its size and dependence: the located
// waveform mismatches at or above `sigma_threshold`.
std::vector<Mismatch> WaveformMismatches(const std::vector<WaveformPoint>& pts, int pole_pairs, double f_inj_hz,
                                         double sigma_threshold);

// ---- corrected.cc -----------------------------------------------------------
fit::FitData CorrectedFitData(const io::RecordingSet& set, const Model& m, const Params& final_p,
                              const std::vector<ident::HfPointResult>& ids);

}  // namespace fluxcal::diag::detail

#endif  // FLUXCAL_DIAGNOSIS_INTERNAL_H_
