#include "diagnosis/diagnose.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <complex>
#include <numbers>

#include <Eigen/Dense>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "ceres/ceres.h"
#include "identification/demod.h"
#include "identification/identify.h"
#include "fitting/fit.h"
#include "identification/inductance.h"
#include "simulation/effects.h"
#include "simulation/frames.h"
#include "simulation/magnetic_model.h"
#include "simulation/twin.h"

namespace fluxcal::diag {
namespace {

using Complex = std::complex<double>;
using sim::kPi;
using sim::kSqrt3;
constexpr double kL0 = 1e-4;    // inductance scale of the surface polynomials [H]
constexpr double kI0 = 100.0;   // current scale [A]
constexpr double kIth = 1.0;    // soft-sign current of the dead-time model [A]

inline double IPow(double x, int n) {
  double r = 1.0;
  for (int k = 0; k < n; ++k) r *= x;
  return r;
}

// ---- Parameter blocks (scaled to order one) -----------------------------
enum Block {
  kBase, kCross, kDead, kRs, kRhf, kOffset, kGain, kPsi, kDelay, kHarm, kSensorOffset, kUdcGain, kRImb, kDrift,
  kNumBlocks
};
constexpr int kBlockSize[kNumBlocks] = {10, 8, 1, 1, 1, 1, 3, 1, 1, 1, 2, 1, 2, 1};
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
// Cross terms x^a y^b of the co-energy (a >= 1, b >= 2 even): they vanish
// with iq = 0 or id = 0 as the machine's symmetry requires.
constexpr int kCrossTerms[8][2] = {{1, 2}, {2, 2}, {3, 2}, {1, 4}, {2, 4}, {4, 2}, {5, 2}, {3, 4}};

struct Candidate {
  std::string effect;
  Block block;
  int order = 0;   // spatial harmonics only
};

// Per-observation data, precomputed from the recording.
struct HfObs {
  std::string point;
  double id_a, iq_a, w_e, theta, speed_rpm;
  Complex i0, i1, v_eff, dead_hf, dead_neg;
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
int HarmIndex(int order) {
  for (int k = 0; k < 4; ++k) if (kHarmOrders[k] == order) return k;
  return -1;
}
struct DcObs {
  std::string point;
  double id_a, iq_a, theta;
  double progress = 0;
  Complex u, dead;                  // dead: command change per second of dead time
  double sigma;
};
struct SsObs {
  double id_a, iq_a, speed_rpm, w_e;
  Complex u, dead;
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
  std::vector<HfObs> hf;
  std::vector<DcObs> dc;
  std::vector<SsObs> ss;
  int harm_order = 6;
  double dc_scale_v = 0.1, torque_scale_nm = 0.1;   // RelativeRms

  // Differential inductance of the surfaces: base self-axis polynomials
  // Ldd(id), Lqq(iq) plus the cross terms of W'_x = L0 I0^2 sum c x^a y^b.
  void Inductance(const double* const* p, double id, double iq, double* ldd, double* lqq, double* ldq) const {
    const double x = id / kI0, y = iq / kI0;
    const double* b = p[kBase];
    const double* c = p[kCross];
    double dd = b[0] + x * (b[1] + x * (b[2] + x * (b[3] + x * b[4])));
    double qq = b[5] + y * (b[6] + y * (b[7] + y * (b[8] + y * b[9])));
    double dq = 0;
    for (int k = 0; k < kBlockSize[kCross]; ++k) {
      const int a = kCrossTerms[k][0], e = kCrossTerms[k][1];
      if (a >= 2) dd += c[k] * a * (a - 1) * IPow(x, a - 2) * IPow(y, e);
      qq += c[k] * e * (e - 1) * IPow(x, a) * IPow(y, e - 2);
      dq += c[k] * a * e * IPow(x, a - 1) * IPow(y, e - 1);
    }
    *ldd = kL0 * dd;
    *lqq = kL0 * qq;
    *ldq = kL0 * dq;
  }
  // Flux linkage: gradient of the same co-energy (psi = grad W').
  void Flux(const double* const* p, double id, double iq, double* pd, double* pq) const {
    const double x = id / kI0, y = iq / kI0;
    const double* b = p[kBase];
    const double* c = p[kCross];
    const double psi_pm = psi_nom * (1 + kScalePsi * p[kPsi][0]);
    double d = x * (b[0] + x * (b[1] / 2 + x * (b[2] / 3 + x * (b[3] / 4 + x * b[4] / 5))));
    double q = y * (b[5] + y * (b[6] / 2 + y * (b[7] / 3 + y * (b[8] / 4 + y * b[9] / 5))));
    for (int k = 0; k < kBlockSize[kCross]; ++k) {
      const int a = kCrossTerms[k][0], e = kCrossTerms[k][1];
      d += c[k] * a * IPow(x, a - 1) * IPow(y, e);
      q += c[k] * e * IPow(x, a) * IPow(y, e - 1);
    }
    *pd = psi_pm + kL0 * kI0 * d;
    *pq = kL0 * kI0 * q;
  }
  double Rs(const double* const* p) const { return rs_nom + kScaleRs * p[kRs][0]; }
  double DeadTime(const double* const* p) const { return dead_nom_s + kScaleDead * p[kDead][0]; }
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
  // sequences: V = R I0 + j w (S I0 + D conj(I1)), Vn = R I1 + j w2 (S I1 + D conj(I0)).
  void SolvePhasors(double ldd, double lqq, double ldq, double r, Complex v, Complex vn, double w_e,
                    Complex* i0, Complex* i1) const {
    const Complex j(0.0, 1.0);
    const double S = 0.5 * (ldd + lqq), w2 = 2.0 * w_e - w_i;
    const Complex D(0.5 * (ldd - lqq), ldq);
    const Complex a1 = r + j * w_i * S, b1 = j * w_i * D, a2 = r + j * w2 * S, b2 = j * w2 * D;
    Eigen::Matrix4d A;
    A << a1.real(), -a1.imag(), b1.real(), b1.imag(),
         a1.imag(), a1.real(), b1.imag(), -b1.real(),
         b2.real(), b2.imag(), a2.real(), -a2.imag(),
         b2.imag(), -b2.real(), a2.imag(), a2.real();
    const Eigen::Vector4d x = A.partialPivLu().solve(Eigen::Vector4d(v.real(), v.imag(), vn.real(), vn.imag()));
    *i0 = Complex(x(0), x(1));
    *i1 = Complex(x(2), x(3));
  }
  // What an extra delay tau of the held (staircase) command does to the
  // phasor of the *sampled* HF current. The current of an inductive load
  // driven by a staircase is piecewise linear with corners at the steps; with
  // tau = (n + a) T, 0 <= a < 1, each sample falls a fraction 1 - a into a
  // segment, so the samples interpolate the undelayed corner values:
  //   i(t_k) = (1 - a) i0(t_{k-n}) + a i0(t_{k-n-1})
  //   => factor e^{-j w n T} ((1 - a) + a e^{-j w T}).
  // Not the pure e^{-j w tau}: at half a sample the magnitude is
  // cos(w T / 2) (-1.2 % at 500 Hz, 10 kHz), which would otherwise be fitted
  // as a 1 % larger inductance. (R T / L << 1, as for any motor winding.)
  Complex StaircaseDelay(double w, double tau_s) const {
    const double q = tau_s / ts, n = std::floor(q), a = q - n;
    return std::polar(1.0, -w * n * ts) * ((1.0 - a) + a * std::polar(1.0, -w * ts));
  }
  void PredictHf(const double* const* p, const HfObs& o, Complex* i0, Complex* i1) const {
    const Complex rot = std::polar(1.0, Offset(p));
    const Complex it = rot * Complex(o.id_a, o.iq_a);   // true-frame current
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
    Complex v = o.v_eff * StaircaseDelay(w_i, Delay(p)) / UdcGain(p) - DeadTime(p) * o.dead_hf;
    Complex vn = -DeadTime(p) * o.dead_neg;
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
    SolvePhasors(ldd, lqq, ldq, r, v, vn, o.w_e, i0, i1);
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
    return UdcGain(p) * (RsAt(p, o.progress) * it + imb + DeadTime(p) * o.dead);
  }
  Complex PredictSs(const double* const* p, const SsObs& o) const {
    const Complex rot = std::polar(1.0, Offset(p));
    const Complex it = rot * Complex(o.id_a, o.iq_a) / M1(p);
    double pd, pq;
    Flux(p, it.real(), it.imag(), &pd, &pq);
    const double rs = RsAt(p, 1.0);   // recorded after the points: the winding is warm
    const Complex u_true(rs * it.real() - o.w_e * pq, rs * it.imag() + o.w_e * pd);
    return UdcGain(p) * (std::conj(rot) * u_true * std::polar(1.0, o.w_e * Delay(p)) + DeadTime(p) * o.dead);
  }
  double PredictTorque(const double* const* p, const SsObs& o) const {
    const Complex it = std::polar(1.0, Offset(p)) * Complex(o.id_a, o.iq_a) / M1(p);
    double pd, pq;
    Flux(p, it.real(), it.imag(), &pd, &pq);
    return 1.5 * pole_pairs * (pd * it.imag() - pq * it.real());
  }
};

// One cost functor per observation (numeric derivatives: the model is a
// small linear solve per point).
class ObservationResidual {
 public:
  ObservationResidual(const Model* m, int kind, int index) : m_(m), kind_(kind), index_(index) {}
  bool operator()(const double* const* p, double* r) const {
    if (kind_ == 0) {
      const auto& o = m_->hf[index_];
      Complex i0, i1;
      m_->PredictHf(p, o, &i0, &i1);
      const Complex d0 = (o.i0 - i0) / o.sigma0, d1 = (o.i1 - i1) / o.sigma1;
      r[0] = d0.real(); r[1] = d0.imag(); r[2] = d1.real(); r[3] = d1.imag();
    } else if (kind_ == 1) {
      const auto& o = m_->dc[index_];
      const Complex d = (o.u - m_->PredictDc(p, o)) / o.sigma;
      r[0] = d.real(); r[1] = d.imag();
    } else if (kind_ == 2) {
      const auto& o = m_->ss[index_];
      const Complex d = (o.u - m_->PredictSs(p, o)) / o.sigma;
      r[0] = d.real(); r[1] = d.imag();
    } else {
      const auto& o = m_->ss[index_];
      r[0] = (o.torque - m_->PredictTorque(p, o)) / o.torque_sigma;
    }
    return true;
  }
  static int NumResiduals(int kind) { return kind == 0 ? 4 : (kind == 3 ? 1 : 2); }

 private:
  const Model* m_;
  int kind_, index_;
};

struct Params {
  std::vector<std::vector<double>> b;
  Params() {
    for (int k = 0; k < kNumBlocks; ++k) b.emplace_back(kBlockSize[k], 0.0);
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
  int k = 0, n = 0;
  std::map<Block, std::vector<double>> stdev;
  bool ok = false;
};

// Relative residual RMS over every observable (dimensionless). HF phasors
// and steady-state voltages are relative to their own magnitude (never near
// zero); held DC voltages and torques are relative to the RMS magnitude of
// their kind over the set (Model::dc_scale_v, torque_scale_nm), because a
// row near zero volts or zero torque would otherwise turn its noise into a
// large relative error and dominate the RMS.
double RelativeRms(const Model& m, const Params& p) {
  const auto ptr = p.Ptrs();
  double s = 0;
  int n = 0;
  for (const auto& o : m.hf) {
    Complex i0, i1;
    m.PredictHf(ptr.data(), o, &i0, &i1);
    s += (std::norm(o.i0 - i0) + std::norm(o.i1 - i1)) / (o.scale * o.scale);
    n += 2;
  }
  for (const auto& o : m.dc) {
    s += std::norm(o.u - m.PredictDc(ptr.data(), o)) / (m.dc_scale_v * m.dc_scale_v);
    ++n;
  }
  for (const auto& o : m.ss) {
    s += std::norm(o.u - m.PredictSs(ptr.data(), o)) / (o.scale * o.scale);
    ++n;
    if (o.has_torque) {
      const double d = (o.torque - m.PredictTorque(ptr.data(), o)) / m.torque_scale_nm;
      s += d * d;
      ++n;
    }
  }
  return n ? std::sqrt(s / n) : 0.0;
}

// Observation kinds, as ObservationResidual numbers them.
enum Kind { kHfKind = 0, kDcKind = 1, kSsKind = 2, kTorqueKind = 3 };
const char* KindSignal(int kind) {
  static const char* names[4] = {"hf_current", "dc_voltage", "steady_state_voltage", "torque"};
  return names[kind];
}

// Least squares over every observation except those of kind `held_out`
// (-1: none), with the blocks in `free_blocks` free.
// Relative residual RMS of one observation kind (normalised as RelativeRms).
double RelativeRmsOf(const Model& m, const Params& p, int kind) {
  const auto ptr = p.Ptrs();
  double s = 0;
  int n = 0;
  if (kind == kDcKind) {
    for (const auto& o : m.dc) { s += std::norm(o.u - m.PredictDc(ptr.data(), o)) / (m.dc_scale_v * m.dc_scale_v); ++n; }
  }
  for (const auto& o : m.ss) {
    if (kind == kSsKind) { s += std::norm(o.u - m.PredictSs(ptr.data(), o)) / (o.scale * o.scale); ++n; }
    if (kind == kTorqueKind && o.has_torque) {
      const double d = (o.torque - m.PredictTorque(ptr.data(), o)) / m.torque_scale_nm;
      s += d * d;
      ++n;
    }
  }
  return n ? std::sqrt(s / n) : 0.0;
}

FitOut Solve(const Model& m, const Params& start, const std::vector<Block>& free_blocks, int held_out = -1) {
  FitOut out;
  out.p = start;
  ceres::Problem problem;
  std::vector<double*> blocks;
  for (auto& x : out.p.b) blocks.push_back(x.data());
  auto add = [&](int kind, int index) {
    if (kind == held_out) return;
    auto* c = new ceres::DynamicNumericDiffCostFunction<ObservationResidual>(new ObservationResidual(&m, kind, index));
    for (int k = 0; k < kNumBlocks; ++k) c->AddParameterBlock(kBlockSize[k]);
    c->SetNumResiduals(ObservationResidual::NumResiduals(kind));
    problem.AddResidualBlock(c, nullptr, blocks);
    out.n += ObservationResidual::NumResiduals(kind);
  };
  for (size_t k = 0; k < m.hf.size(); ++k) add(0, static_cast<int>(k));
  for (size_t k = 0; k < m.dc.size(); ++k) add(1, static_cast<int>(k));
  for (size_t k = 0; k < m.ss.size(); ++k) {
    add(2, static_cast<int>(k));
    if (m.ss[k].has_torque) add(3, static_cast<int>(k));
  }
  for (int k = 0; k < kNumBlocks; ++k) {
    const bool free = std::find(free_blocks.begin(), free_blocks.end(), static_cast<Block>(k)) != free_blocks.end();
    if (!free) problem.SetParameterBlockConstant(blocks[k]);
    else out.k += kBlockSize[k];
  }
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = 60;
  so.function_tolerance = 1e-10;
  so.logging_type = ceres::SILENT;
  ceres::Solver::Summary sum;
  ceres::Solve(so, &problem, &sum);
  out.ok = sum.IsSolutionUsable();
  out.chi2 = 2 * sum.final_cost;
  // BIC with the noise scale estimated from the data (Gaussian likelihood
  // with unknown variance): n ln(chi2/n) + k ln n. The stated sigmas fix the
  // relative weights of the observables; their common scale is what the
  // data say, so a model error shared by all points cannot pose as physics.
  out.bic = out.n * std::log(std::max(out.chi2, 1e-300) / std::max(1, out.n)) + out.k * std::log(std::max(1, out.n));
  out.rms = RelativeRms(m, out.p);
  // Standard deviations of the effect parameters (not the base surfaces),
  // scaled by the reduced chi^2 when the fit is worse than the noise model.
  ceres::Covariance::Options co;
  co.algorithm_type = ceres::DENSE_SVD;
  co.null_space_rank = -1;
  ceres::Covariance cov(co);
  std::vector<std::pair<const double*, const double*>> pairs;
  for (Block b : free_blocks) if (b != kBase && b != kCross) pairs.push_back({blocks[b], blocks[b]});
  if (!pairs.empty() && cov.Compute(pairs, &problem)) {
    const double scale = std::max(1.0, out.chi2 / std::max(1, out.n - out.k));
    for (Block b : free_blocks) {
      if (b == kBase || b == kCross) continue;
      std::vector<double> c(kBlockSize[b] * kBlockSize[b]);
      cov.GetCovarianceBlock(blocks[b], blocks[b], c.data());
      std::vector<double> sd;
      for (int i = 0; i < kBlockSize[b]; ++i) sd.push_back(std::sqrt(std::max(0.0, c[i * kBlockSize[b] + i] * scale)));
      out.stdev[b] = sd;
    }
  }
  return out;
}

// Per-observation normalised residuals (per real component) for locating.
struct Z {
  std::string point, signal;
  double id_a, iq_a, speed_rpm, z2;
  int dof;
};
std::vector<Z> Residuals(const Model& m, const Params& p) {
  const auto ptr = p.Ptrs();
  std::vector<Z> out;
  for (const auto& o : m.hf) {
    Complex i0, i1;
    m.PredictHf(ptr.data(), o, &i0, &i1);
    out.push_back({o.point, "hf_current", o.id_a, o.iq_a, o.speed_rpm,
                   std::norm((o.i0 - i0) / o.sigma0) + std::norm((o.i1 - i1) / o.sigma1), 4});
  }
  for (const auto& o : m.dc) {
    out.push_back({o.point, "dc_voltage", o.id_a, o.iq_a, 0.0, std::norm((o.u - m.PredictDc(ptr.data(), o)) / o.sigma), 2});
  }
  for (size_t k = 0; k < m.ss.size(); ++k) {
    const auto& o = m.ss[k];
    const std::string id = absl::StrFormat("steady_state[%d]", k);
    out.push_back({id, "steady_state_voltage", o.id_a, o.iq_a, o.speed_rpm,
                   std::norm((o.u - m.PredictSs(ptr.data(), o)) / o.sigma), 2});
    if (o.has_torque) {
      const double d = (o.torque - m.PredictTorque(ptr.data(), o)) / o.torque_sigma;
      out.push_back({id, "torque", o.id_a, o.iq_a, o.speed_rpm, d * d, 1});
    }
  }
  return out;
}

// Regions of the operating space where mismatches are located, and the
// chi^2 of the normalised residuals in each against its degrees of freedom.
struct RegionStat {
  std::string signal, where;
  double chi2 = 0;
  int k = 0;
  std::vector<std::pair<double, std::string>> points;   // (z^2 per dof, point)
  // Gaussian significance of the excess, (chi2 - k) / sqrt(2k).
  double Sigma() const { return k ? (chi2 - k) / std::sqrt(2.0 * k) : 0.0; }
};
std::vector<RegionStat> RegionStats(const std::vector<Z>& zs) {
  struct Region { std::string signal, where; std::function<bool(const Z&)> in; };
  auto mag = [](const Z& z) { return std::hypot(z.id_a, z.iq_a); };
  const std::vector<Region> regions = {
      {"hf_current", "low fundamental current, |i| < 25 A, standstill", [&](const Z& z) { return z.speed_rpm == 0 && mag(z) < 25; }},
      {"hf_current", "high fundamental current, |i| >= 25 A, standstill", [&](const Z& z) { return z.speed_rpm == 0 && mag(z) >= 25; }},
      {"hf_current", "rotating points", [&](const Z& z) { return z.speed_rpm != 0; }},
      {"dc_voltage", "low fundamental current, |i| < 25 A, standstill", [&](const Z& z) { return mag(z) < 25; }},
      {"dc_voltage", "high fundamental current, |i| >= 25 A, standstill", [&](const Z& z) { return mag(z) >= 25; }},
      {"steady_state_voltage", "steady state at speed", [](const Z&) { return true; }},
      {"torque", "steady state at speed", [](const Z&) { return true; }},
  };
  std::vector<RegionStat> out;
  for (const auto& r : regions) {
    RegionStat st;
    st.signal = r.signal;
    st.where = r.where;
    for (const auto& z : zs) {
      if (z.signal != r.signal || !r.in(z)) continue;
      st.chi2 += z.z2;
      st.k += z.dof;
      st.points.push_back({z.z2 / z.dof, z.point});
    }
    out.push_back(std::move(st));
  }
  return out;
}

// Regions whose significance reaches `threshold`.
std::vector<Mismatch> Locate(const std::vector<Z>& zs, double threshold) {
  std::vector<Mismatch> out;
  for (auto& r : RegionStats(zs)) {
    if (r.k == 0 || r.Sigma() < threshold) continue;
    std::sort(r.points.rbegin(), r.points.rend());
    Mismatch mm;
    mm.signal = r.signal;
    mm.where = r.where;
    mm.significance_sigma = r.Sigma();
    for (const auto& [v, name] : r.points) if (v > 4.0 && mm.points.size() < 12) mm.points.push_back(name);
    out.push_back(mm);
  }
  return out;
}

// Practical significance of a candidate (beyond BIC and the parameter's
// distance from neutral): it must explain a real share of what is wrong.
// Either the relative residual RMS over every observable falls by
// `min_relative_improvement`, or the candidate removes at least half of the
// chi^2 excess of a region that is located as mismatched. The second form
// keeps one unexplained gross region (or noisy torque rows near zero torque,
// which dominate a relative RMS) from hiding an effect that clearly explains
// another region.
bool PracticallySignificant(const std::vector<Z>& before, const std::vector<Z>& after, double rms_before,
                            double rms_after, const DiagnoseOptions& opt) {
  if (rms_after <= (1.0 - opt.min_relative_improvement) * rms_before) return true;
  const auto rb = RegionStats(before), ra = RegionStats(after);
  for (size_t k = 0; k < rb.size(); ++k) {
    if (rb[k].k == 0 || rb[k].Sigma() < opt.mismatch_sigma) continue;
    const double excess_before = rb[k].chi2 - rb[k].k, excess_after = ra[k].chi2 - ra[k].k;
    if (excess_after <= 0.5 * excess_before) return true;
  }
  return false;
}

// The dead-time voltage error per second of dead time, in the command's
// units: (Udc/Ts) Clarke(tanh(i_x / i_th)) -- the command must add this to
// hold the current when Td is not compensated.
Complex DeadTimeUnit(double ia, double ib, double ic, double udc, double ts) {
  const double k = udc / ts;
  const double ea = k * std::tanh(ia / kIth), eb = k * std::tanh(ib / kIth), ec = k * std::tanh(ic / kIth);
  return Complex((2 * ea - eb - ec) / 3.0, (eb - ec) / kSqrt3);
}

// Mean of tanh(i/i_th) over a PWM period in which the current moves
// linearly from i0 to i1: (i_th / (i1 - i0)) [ln cosh(i1/i_th) - ln cosh(i0/i_th)].
// The HF ripple moves a phase current by ~2 A within one period, as much as
// the soft-sign width, so the start-of-period sample is not enough.
double MeanSoftSign(double i0, double i1) {
  const double d = i1 - i0;
  auto lc = [](double x) { const double a = std::abs(x); return a + std::log1p(std::exp(-2 * a)) - std::log(2.0); };
  if (std::abs(d) < 1e-6 * kIth) return std::tanh(0.5 * (i0 + i1) / kIth);
  return kIth / d * (lc(i1 / kIth) - lc(i0 / kIth));
}

Complex DeadTimeInterval(const io::Waveform& w, size_t s, double udc, double ts) {
  const size_t e = s + 1 < w.size() ? s + 1 : s;
  const double k = udc / ts;
  const double ea = k * MeanSoftSign(w.ia_a[s], w.ia_a[e]), eb = k * MeanSoftSign(w.ib_a[s], w.ib_a[e]),
               ec = k * MeanSoftSign(w.ic_a[s], w.ic_a[e]);
  return Complex((2 * ea - eb - ec) / 3.0, (eb - ec) / kSqrt3);
}

absl::StatusOr<Model> BuildModel(const io::RecordingSet& set, std::vector<ident::HfPointResult>* ids) {
  const auto& mf = set.manifest;
  Model m;
  m.pole_pairs = mf.motor.pole_pairs;
  m.rs_nom = mf.motor.rs_ohm.value_or(0.0);
  m.psi_nom = mf.motor.psi_pm_wb.value_or(0.01);
  if (mf.drive.dead_time_compensated.has_value() && !*mf.drive.dead_time_compensated) {
    m.dead_nom_s = mf.drive.dead_time_s.value_or(0.0);
  }
  const double fs = mf.drive.f_sample_hz;
  const double f_pwm = mf.drive.f_pwm_hz.value_or(fs);
  m.ts = 1.0 / f_pwm;
  const double udc_nom = mf.drive.udc_v.value_or(0.0);
  if (mf.injection) m.w_i = 2 * kPi * mf.injection->frequency_hz;
  auto r = ident::IdentifySet(set, {});
  if (!r.ok()) return r.status();
  *ids = *r;
  for (size_t k = 0; k < ids->size(); ++k) {
    const auto& id = (*ids)[k];
    const auto& w = set.waveforms[k];
    if (!std::isfinite(id.ld_h) || !std::isfinite(id.id_a)) continue;   // identification_failed
    HfObs o;
    o.point = id.point;
    o.id_a = id.id_a; o.iq_a = id.iq_a;
    o.speed_rpm = std::abs(id.speed_rpm) < 5 ? 0.0 : id.speed_rpm;
    o.w_e = o.speed_rpm == 0 ? 0.0 : id.speed_rpm * m.pole_pairs * 2 * kPi / 60;
    o.locked = o.speed_rpm == 0;
    o.theta = w.theta_e_rad[0];
    // The manifest lists points in recording order.
    o.progress = ids->size() > 1 ? static_cast<double>(k) / static_cast<double>(ids->size() - 1) : 0.0;
    o.i0 = id.i0_a; o.i1 = id.i1_a; o.v_eff = id.v_eff_v;
    o.mean_e2 = 0.0;
    // Noise from the data (LSQ standard error) plus a model floor of 0.25 %
    // of |I0|: the identification's own systematic accuracy on clean twin
    // and independent data (docs/identification.md).
    ident::PhaseSamples ps{w.ia_a.data(), w.ib_a.data(), w.ic_a.data(), w.theta_e_rad.data(), w.size(), fs,
                           mf.injection->frequency_hz};
    auto lsq = ident::LsqDemodulate(ps);
    if (!lsq.ok()) return lsq.status();
    // Points where a phase current lingers near zero (the paper's Sec. 3.3)
    // carry HF distortion beyond any linear model: 2 % floor there.
    const bool near_zero = std::find(id.flags.begin(), id.flags.end(), "phase_current_near_zero") != id.flags.end();
    const double floor = (near_zero ? 0.02 : 0.0025) * std::abs(o.i0);
    o.sigma0 = std::sqrt(lsq->var_i0_a2 + floor * floor);
    o.sigma1 = std::sqrt(lsq->var_i1_a2 + floor * floor);
    o.scale = std::abs(o.i0);
    // Dead-time signatures from the recorded phase currents.
    const size_t n = lsq->samples_used;
    Complex hf = 0, neg = 0, dc = 0;
    std::vector<Complex> per_period;
    const size_t period = static_cast<size_t>(std::llround(fs / mf.injection->frequency_hz));
    Complex acc_u = 0;
    for (size_t s = 0; s < n; ++s) {
      const double udc = std::isnan(w.udc_v[s]) ? udc_nom : w.udc_v[s];
      const Complex e = DeadTimeInterval(w, s, udc, m.ts);
      const double t = static_cast<double>(s) / fs;
      hf += e * std::polar(1.0, -m.w_i * t);
      o.mean_e2 += std::polar(1.0, -2 * w.theta_e_rad[s]);
      if (!o.locked) {
        for (int h = 0; h < 4; ++h) {
          const int nh = kHarmOrders[h];
          o.harm_p[h] += std::polar(1.0, (nh + 1) * w.theta_e_rad[s] - m.w_i * t);
          o.harm_q[h] += std::polar(1.0, -(nh - 1) * w.theta_e_rad[s] - m.w_i * t);
        }
      }
      neg += e * std::polar(1.0, m.w_i * t - 2 * w.theta_e_rad[s]);
      dc += e * std::polar(1.0, -w.theta_e_rad[s]);
      acc_u += Complex(w.ualpha_ref_v[s], w.ubeta_ref_v[s]) * std::polar(1.0, -w.theta_e_rad[s]);
      if ((s + 1) % period == 0) { per_period.push_back(acc_u / static_cast<double>(period)); acc_u = 0; }
    }
    // The error of interval [t_k, t_k+1) acts in that interval, one period
    // earlier than a command issued at t_k: EffectiveVoltage's 1.5-period
    // delay less one period.
    const double w2 = 2 * o.w_e - m.w_i;
    o.mean_e2 /= static_cast<double>(n);
    for (int h = 0; h < 4; ++h) {
      o.harm_p[h] /= static_cast<double>(n);
      o.harm_q[h] /= static_cast<double>(n);
    }
    o.dead_hf = ident::EffectiveVoltage(hf / static_cast<double>(n), m.w_i, f_pwm) * std::polar(1.0, m.w_i * m.ts);
    o.dead_neg = ident::EffectiveVoltage(neg / static_cast<double>(n), w2, f_pwm) * std::polar(1.0, w2 * m.ts);
    m.hf.push_back(o);
    if (o.locked && per_period.size() >= 4) {
      DcObs d;
      d.point = id.point;
      d.id_a = id.id_a; d.iq_a = id.iq_a;
      d.theta = w.theta_e_rad[0];
      d.progress = o.progress;
      Complex mean = 0;
      for (const auto& u : per_period) mean += u;
      mean /= static_cast<double>(per_period.size());
      double var = 0;
      for (const auto& u : per_period) var += std::norm(u - mean);
      var /= static_cast<double>(per_period.size() - 1) * per_period.size();
      d.u = mean;
      d.dead = dc / static_cast<double>(n);
      // Batch-means noise plus 5 mV: the command's resolution after the
      // bench's own (nominal) dead-time compensation and quantisation.
      d.sigma = std::sqrt(var + 0.005 * 0.005);
      m.dc.push_back(d);
    }
  }
  for (const auto& row : set.steady_state) {
    SsObs o;
    o.id_a = row.id_a; o.iq_a = row.iq_a; o.speed_rpm = row.speed_rpm;
    o.w_e = row.speed_rpm * m.pole_pairs * 2 * kPi / 60;
    o.u = sim::ZohGain(o.w_e, m.ts) * Complex(row.ud_ref_v, row.uq_ref_v);
    // Fundamental of the dead-time error over one electrical revolution.
    Complex dead = 0;
    const double mag = std::hypot(o.id_a, o.iq_a), gam = std::atan2(o.iq_a, o.id_a);
    for (int s = 0; s < 360; ++s) {
      const double th = 2 * kPi * s / 360;
      const double ia = mag * std::cos(th + gam), ib = mag * std::cos(th + gam - 2 * kPi / 3),
                   ic = mag * std::cos(th + gam + 2 * kPi / 3);
      dead += DeadTimeUnit(ia, ib, ic, udc_nom, m.ts) * std::polar(1.0, -th);
    }
    o.dead = dead / 360.0;
    o.scale = std::abs(o.u);
    // 20 mV and 0.3 % of the voltage: averaged commands, nominal Rs and
    // the bench's delay compensation.
    o.sigma = 0.02 + 0.003 * std::abs(o.u);
    o.has_torque = row.torque_nm.has_value();
    o.torque = row.torque_nm.value_or(0.0);
    o.torque_sigma = 0.02 + 0.005 * std::abs(o.torque);
    m.ss.push_back(o);
  }
  double dc2 = 0, t2 = 0;
  int nt = 0;
  for (const auto& d : m.dc) dc2 += std::norm(d.u);
  for (const auto& o : m.ss) if (o.has_torque) { t2 += o.torque * o.torque; ++nt; }
  if (!m.dc.empty()) m.dc_scale_v = std::max(0.01, std::sqrt(dc2 / m.dc.size()));
  if (nt) m.torque_scale_nm = std::max(0.1, std::sqrt(t2 / nt));
  return m;
}

void InitBase(const Model& m, const std::vector<ident::HfPointResult>& all_ids, Params* p) {
  // Quartic self-axis surfaces by least squares on the identified values.
  std::vector<ident::HfPointResult> ok;
  for (const auto& r : all_ids) if (std::isfinite(r.ld_h) && std::isfinite(r.id_a)) ok.push_back(r);
  const auto& ids = ok;
  Eigen::MatrixXd A(ids.size(), 5), B(ids.size(), 5);
  Eigen::VectorXd a(ids.size()), b(ids.size());
  for (size_t k = 0; k < ids.size(); ++k) {
    const double x = ids[k].id_a / kI0, y = ids[k].iq_a / kI0;
    A.row(k) << 1, x, x * x, x * x * x, x * x * x * x;
    B.row(k) << 1, y, y * y, y * y * y, y * y * y * y;
    a(k) = ids[k].ld_h / kL0;
    b(k) = ids[k].lq_h / kL0;
  }
  const Eigen::VectorXd ca = A.colPivHouseholderQr().solve(a), cb = B.colPivHouseholderQr().solve(b);
  for (int k = 0; k < 5; ++k) { p->b[kBase][k] = ca(k); p->b[kBase][5 + k] = cb(k); }
  (void)m;
}

// The three phase gains of m1, m2 (g_x = m1 + 2 Re(m2 e^{-j 2 phi_x}), sum of
// the deviations zero) and the zero-sum phase offsets of an alpha-beta
// offset o (o_x = Re(o e^{-j phi_x})).
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
  const auto ptr = f.p.Ptrs();
  const double* const* p = ptr.data();
  switch (c.block) {
    case kDead:
      // Effective dead time acting (declared uncompensated part included).
      out.parameters["dead_time_s"] = m.DeadTime(p);
      out.parameter_std["dead_time_s"] = kScaleDead * sd(kDead, 0);
      break;
    case kRs:
      out.parameters["rs_ohm"] = m.Rs(p);
      out.parameter_std["rs_ohm"] = kScaleRs * sd(kRs, 0);
      break;
    case kRhf:
      out.parameters["r_hf_ohm"] = m.RHf(p);
      out.parameter_std["r_hf_ohm"] = kScaleRhf * sd(kRhf, 0);
      break;
    case kOffset:
      out.parameters["offset_rad"] = m.Offset(p);
      out.parameter_std["offset_rad"] = kScaleOffset * sd(kOffset, 0);
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
      out.parameters["psi_pm_wb"] = m.psi_nom * (1 + kScalePsi * p[kPsi][0]);
      out.parameter_std["psi_pm_wb"] = m.psi_nom * kScalePsi * sd(kPsi, 0);
      break;
    case kDelay:
      out.parameters["delay_s"] = m.Delay(p);
      out.parameter_std["delay_s"] = kScaleDelay * sd(kDelay, 0);
      break;
    case kHarm:
      out.parameters["order"] = c.order;
      out.parameters["amplitude_h"] = m.Harm(p);
      out.parameter_std["amplitude_h"] = kScaleHarm * sd(kHarm, 0);
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
      out.parameters["udc_sense_gain"] = m.UdcGain(p);
      out.parameter_std["udc_sense_gain"] = kScaleUdcGain * sd(kUdcGain, 0);
      break;
    case kRImb: {
      // dr_x = 2 Re(r2 e^{-j 2 phi_x}), the zero-sum set (the common part is Rs).
      const char* names[3] = {"dr_a_ohm", "dr_b_ohm", "dr_c_ohm"};
      const double sdr = kScaleRImb * std::max(sd(kRImb, 0), sd(kRImb, 1));
      for (int x = 0; x < 3; ++x) {
        out.parameters[names[x]] = 2 * std::real(m.RImb(p) * std::polar(1.0, -2 * kPhasePhi[x]));
        out.parameter_std[names[x]] = 2 * sdr;
      }
      break;
    }
    case kDrift:
      out.parameters["winding_temp_rise_k"] = kScaleDrift * p[kDrift][0];
      out.parameter_std["winding_temp_rise_k"] = kScaleDrift * sd(kDrift, 0);
      break;
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
// Cross saturation has no single parameter: it counts when the cross
// coupling it fits is material, max |Ldq| over the measured points above the
// identification's own Ldq accuracy (1 % of the mean inductance,
// tests/identification); expressed on the same 3-sigma scale.
double Significance(const Candidate& c, const FitOut& f, const Model& m) {
  if (c.block == kCross) {
    const auto ptr = f.p.Ptrs();
    double max_ldq = 0, mean_l = 0;
    for (const auto& o : m.hf) {
      double ldd, lqq, ldq;
      m.Inductance(ptr.data(), o.id_a, o.iq_a, &ldd, &lqq, &ldq);
      max_ldq = std::max(max_ldq, std::abs(ldq));
      mean_l += 0.5 * (ldd + lqq) / m.hf.size();
    }
    return 3.0 * max_ldq / (0.01 * mean_l);
  }
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

// The fitted surfaces as a twin magnetic model (for waveform replay).
class SurfaceModel : public sim::MagneticModel {
 public:
  SurfaceModel(const Model& m, const Params& p) : m_(m), p_(p), ptr_(p_.Ptrs()) {}
  sim::FluxLinkage Flux(double id, double iq, double) const override {
    sim::FluxLinkage f;
    m_.Flux(ptr_.data(), id, iq, &f.psi_d_wb, &f.psi_q_wb);
    return f;
  }
  sim::DifferentialInductance Inductance(double id, double iq, double) const override {
    sim::DifferentialInductance l;
    m_.Inductance(ptr_.data(), id, iq, &l.ldd_h, &l.lqq_h, &l.ldq_h);
    return l;
  }
 private:
  const Model& m_;
  Params p_;
  std::vector<const double*> ptr_;
};

// Replays every waveform point with the model and effects of `p`; returns
// the overall RMS of simulated minus recorded phase currents and fills the
// residual spectrum at `freqs` (mean over points of |DFT| of the complex
// alpha-beta residual, in A).
double ReplayResidual(const io::RecordingSet& set, const Model& m, const Params& p, int harm_order,
                      const std::vector<double>& freqs, std::vector<double>* spectrum) {
  SurfaceModel model(m, p);
  const auto ptr = p.Ptrs();
  sim::ReplayOptions opt;
  opt.substeps = 5;   // RK4 at 20 us: w_i h = 0.06, far inside its accuracy
  opt.rs_ohm = m.Rs(ptr.data());
  opt.effects.dead_time_s = m.DeadTime(ptr.data());
  opt.effects.dead_time_i_th_a = kIth;
  opt.effects.offset_rad = m.Offset(ptr.data());
  opt.effects.delay_s = m.Delay(ptr.data());
  opt.effects.r_hf_ohm = m.RHf(ptr.data());
  opt.effects.order = ptr[kHarm][0] != 0.0 ? harm_order : 0;
  opt.effects.amplitude_h = m.Harm(ptr.data());
  opt.effects.udc_sense_gain = m.UdcGain(ptr.data());
  for (int x = 0; x < 3; ++x) {
    double* dr[3] = {&opt.effects.dr_a_ohm, &opt.effects.dr_b_ohm, &opt.effects.dr_c_ohm};
    *dr[x] = 2 * std::real(m.RImb(ptr.data()) * std::polar(1.0, -2 * kPhasePhi[x]));
  }
  const Complex so = m.SensorOffset(ptr.data());
  opt.effects.offset_a_a = PhaseOffset(so, 0);
  opt.effects.offset_b_a = PhaseOffset(so, 1);
  opt.effects.offset_c_a = PhaseOffset(so, 2);
  double* g[3] = {&opt.effects.gain_a, &opt.effects.gain_b, &opt.effects.gain_c};
  for (int x = 0; x < 3; ++x) *g[x] = PhaseGain(m.M1(ptr.data()), m.M2(ptr.data()), x);
  auto rep = sim::ReplayOpenLoop(set, model, opt);
  spectrum->assign(freqs.size(), 0.0);
  if (!rep.ok()) return std::nan("");
  double se = 0;
  size_t n_all = 0;
  const double fs = set.manifest.drive.f_sample_hz;
  for (size_t k = 0; k < rep->size(); ++k) {
    const auto& r = (*rep)[k];
    const auto& w = set.waveforms[k];
    se += r.residual_rms_a * r.residual_rms_a * 3.0 * (w.size() - 1);
    n_all += 3 * (w.size() - 1);
    std::vector<Complex> e(w.size());
    for (size_t s = 1; s < w.size(); ++s) {
      const double ea = r.ia_a[s] - w.ia_a[s], eb = r.ib_a[s] - w.ib_a[s], ec = r.ic_a[s] - w.ic_a[s];
      e[s] = Complex((2 * ea - eb - ec) / 3.0, (eb - ec) / kSqrt3);
    }
    for (size_t f = 0; f < freqs.size(); ++f) {
      // DFT bin by a rotating phasor (recurrence, renormalised).
      const Complex step = std::polar(1.0, -2 * kPi * freqs[f] / fs);
      Complex rot = step, acc = 0;
      for (size_t s = 1; s < w.size(); ++s) {
        acc += e[s] * rot;
        rot *= step;
      }
      (*spectrum)[f] += std::abs(acc) / static_cast<double>(w.size() - 1) / static_cast<double>(rep->size());
    }
  }
  return n_all ? std::sqrt(se / n_all) : 0.0;
}

// The recording's fit data (fitting::FitDataFromRecording) freed of the
// measurement and drive effects the diagnosis found, for a refit through the
// fit's own families (docs/diagnosis.md, "The diagnosed calibration"). Each
// observation keeps its own noise; only the effects' share is removed:
//  - inductances: identified + (what identification would give from the
//    final model's phasors without the effects, at the true current) -
//    (the same with them);
//  - steady-state rows: at the true current (angle offset and sensor gains
//    undone), voltage minus the effects' share of the final model's
//    prediction;
//  - Rs and psi_pm: the final model's (motor properties, not artefacts).
fit::FitData CorrectedFitData(const io::RecordingSet& set, const Model& m, const Params& final_p,
                              const std::vector<ident::HfPointResult>& ids) {
  fit::FitData d = fit::FitDataFromRecording(set, ids);
  Model mc = m;
  mc.dead_nom_s = 0.0;   // no dead time acts in the clean model
  Params clean = final_p;
  for (Block b : {kDead, kRhf, kOffset, kGain, kDelay, kHarm, kSensorOffset, kUdcGain, kRImb, kDrift}) {
    std::fill(clean.b[b].begin(), clean.b[b].end(), 0.0);
  }
  const auto pf = final_p.Ptrs(), pc = clean.Ptrs();
  d.rs_ohm = m.Rs(pf.data());
  d.psi_pm_prior_wb = m.psi_nom * (1 + kScalePsi * final_p.b[kPsi][0]);
  const Complex rot = std::polar(1.0, m.Offset(pf.data()));
  // Inductances: FitDataFromRecording keeps the identified points in order,
  // skipping the ones it rejects; match by operating point.
  for (auto& obs : d.inductances) {
    const HfObs* o = nullptr;
    for (const auto& h : m.hf) {
      if (std::abs(h.id_a - obs.id_a) < 1e-9 && std::abs(h.iq_a - obs.iq_a) < 1e-9) o = &h;
    }
    if (o == nullptr) continue;
    Complex i0e, i1e, i0c, i1c;
    m.PredictHf(pf.data(), *o, &i0e, &i1e);
    HfObs oc = *o;
    const Complex it = rot * (o->locked ? m.TrueCurrent(pf.data(), Complex(o->id_a, o->iq_a), o->theta)
                                        : Complex(o->id_a, o->iq_a) / m.M1(pf.data()));
    oc.id_a = it.real();
    oc.iq_a = it.imag();
    oc.theta = o->theta - m.Offset(pf.data());
    mc.PredictHf(pc.data(), oc, &i0c, &i1c);
    auto le = ident::InductanceFromPhasors(i0e, i1e, o->v_eff, m.w_i, o->w_e);
    auto lc = ident::InductanceFromPhasors(i0c, i1c, o->v_eff, m.w_i, o->w_e);
    if (!le.ok() || !lc.ok()) continue;
    obs.id_a = oc.id_a;
    obs.iq_a = oc.iq_a;
    obs.ldd_h += lc->ldd_h - le->ldd_h;
    obs.lqq_h += lc->lqq_h - le->lqq_h;
    if (obs.ldq_h) *obs.ldq_h += lc->ldq_h - le->ldq_h;
  }
  for (size_t k = 0; k < d.steady_state.size() && k < m.ss.size(); ++k) {
    const SsObs& o = m.ss[k];
    SsObs oc = o;
    const Complex it = rot * Complex(o.id_a, o.iq_a) / m.M1(pf.data());
    oc.id_a = it.real();
    oc.iq_a = it.imag();
    const Complex u_corr = o.u - m.PredictSs(pf.data(), o) + mc.PredictSs(pc.data(), oc);
    const double zoh = sim::ZohGain(o.w_e, m.ts);   // o.u = zoh x the row's command
    auto& row = d.steady_state[k];
    row.id_a = it.real();
    row.iq_a = it.imag();
    row.ud_ref_v = u_corr.real() / zoh;
    row.uq_ref_v = u_corr.imag() / zoh;
  }
  return d;
}

}  // namespace

absl::StatusOr<fit::Calibration> DiagnosedCalibration(const DiagnosisReport& r, const fit::FitOptions& options) {
  if (r.corrected_data.inductances.empty() && r.corrected_data.steady_state.empty()) {
    return absl::FailedPreconditionError("diagnosis: no corrected data to fit (run Diagnose first)");
  }
  return fit::Fit(r.corrected_data, options);
}

absl::StatusOr<DiagnosisReport> Diagnose(const io::RecordingSet& set, const DiagnoseOptions& opt) {
  const auto t0 = std::chrono::steady_clock::now();
  if (set.waveforms.empty()) {
    return absl::InvalidArgumentError("field 'points': diagnosis needs waveform points");
  }
  std::vector<ident::HfPointResult> ids;
  auto model = BuildModel(set, &ids);
  if (!model.ok()) return model.status();
  Model& m = *model;
  DiagnosisReport rep;
  rep.serial = set.manifest.serial;

  Params start;
  InitBase(m, ids, &start);
  std::vector<Block> free = {kBase};
  FitOut base = Solve(m, start, free);
  rep.baseline = {"nominal", base.rms, base.bic, base.chi2};
  const auto z_before = Residuals(m, base.p);
  rep.mismatches = Locate(z_before, opt.mismatch_sigma);

  std::vector<Candidate> cands = {
      {"dead_time", kDead}, {"cross_saturation", kCross}, {"stator_resistance", kRs},
      {"hf_resistance", kRhf}, {"position_offset", kOffset}, {"current_sensor_gain", kGain},
      {"magnet_temperature", kPsi}, {"sampling_delay", kDelay},
      {"spatial_harmonics", kHarm, 4}, {"spatial_harmonics", kHarm, 6}, {"spatial_harmonics", kHarm, 8},
      {"spatial_harmonics", kHarm, 12}, {"current_sensor_offset", kSensorOffset},
      {"dc_link_sense_gain", kUdcGain}, {"phase_resistance_imbalance", kRImb},
      {"stator_temperature_drift", kDrift}};
  cands.erase(std::remove_if(cands.begin(), cands.end(),
                             [&](const Candidate& c) {
                               return opt.excluded_effects.count(c.effect) > 0 ||
                                      (m.ss.empty() && c.effect == "magnet_temperature");
                             }),
              cands.end());
  FitOut current = base;
  std::vector<std::string> model_name = {"nominal"};
  std::vector<bool> used(cands.size(), false);
  std::vector<size_t> accepted;   // candidate index per finding
  // Stepwise selection: forward rounds (best candidate by BIC among those
  // that pass every test) until none qualifies, then one backward round:
  // a finding that is no longer material or significant in the joint fit,
  // or whose removal (the others refitted) costs less than the BIC
  // threshold, is dropped -- an effect accepted early can turn out to be a
  // stand-in for a pair accepted later (a constant angle offset for the
  // speed-proportional rotation of a delay at mid speed). Dropped
  // candidates are not tried again, so this ends.
  for (int pass = 0; pass < 4; ++pass) {
  while (true) {
    int best = -1;
    FitOut best_fit;
    // The current model's residuals, once per round (candidates compare to them).
    const auto z_current = Residuals(m, current.p);
    std::vector<RejectedCandidate> round_rejected;
    for (size_t c = 0; c < cands.size(); ++c) {
      if (used[c]) continue;
      if (std::find(free.begin(), free.end(), cands[c].block) != free.end()) continue;
      if (cands[c].block == kHarm) m.harm_order = cands[c].order;
      std::vector<Block> trial = free;
      trial.push_back(cands[c].block);
      Params st = current.p;
      if (cands[c].block == kHarm) st.b[kHarm][0] = 0.0;
      FitOut f = Solve(m, st, trial);
      if (!f.ok) continue;
      const double dbic = f.bic - current.bic;
      const double sig = Significance(cands[c], f, m);
      std::string why;
      if (dbic > -opt.bic_threshold) {
        why = absl::StrFormat("BIC improves by %.1f, not more than %.0f", -dbic, opt.bic_threshold);
      } else if (sig < opt.parameter_sigma) {
        why = sig == 0.0 ? (Plausible(cands[c], f, m)
                                ? "its fitted size is below the catalogue's materiality floor"
                                : "its fitted value is physically implausible (below the catalogue's plausible range)")
                         : absl::StrFormat("its parameter is %.1f standard deviations from neutral, below %.0f", sig,
                                           opt.parameter_sigma);
      } else if (!PracticallySignificant(z_current, Residuals(m, f.p), current.rms, f.rms, opt)) {
        why = "it lowers neither the residual RMS by 10 % nor half of a located region's excess";
      }
      if (!why.empty()) {
        std::string name = cands[c].effect;
        if (cands[c].block == kHarm) name += absl::StrFormat(" (order %d)", cands[c].order);
        round_rejected.push_back({name, why, dbic, sig});
        continue;
      }
      if (best < 0 || f.bic < best_fit.bic) { best = static_cast<int>(c); best_fit = f; }
    }
    if (best < 0) {
      // The best rejected candidates of the last round, by BIC.
      std::sort(round_rejected.begin(), round_rejected.end(),
                [](const RejectedCandidate& a, const RejectedCandidate& b) { return a.delta_bic < b.delta_bic; });
      if (round_rejected.size() > 3) round_rejected.resize(3);
      rep.rejected = round_rejected;
      break;
    }
    used[best] = true;
    if (cands[best].block == kHarm) m.harm_order = cands[best].order;
    free.push_back(cands[best].block);
    Finding fd = Describe(cands[best], m, best_fit);
    fd.residual_rms_before = current.rms;
    fd.residual_rms_after = best_fit.rms;
    fd.delta_bic = best_fit.bic - current.bic;
    rep.findings.push_back(fd);
    model_name.push_back(cands[best].effect);
    accepted.push_back(static_cast<size_t>(best));
    current = best_fit;
  }
  int drop = -1;
  FitOut drop_fit;
  double drop_cost = opt.bic_threshold;
  for (size_t a = 0; accepted.size() >= 2 && a < accepted.size(); ++a) {
    const Block b = cands[accepted[a]].block;
    std::vector<Block> trial;
    for (Block x : free) if (x != b) trial.push_back(x);
    Params st = current.p;
    std::fill(st.b[b].begin(), st.b[b].end(), 0.0);
    const FitOut f = Solve(m, st, trial);
    if (!f.ok) continue;
    // A finding no longer material or significant beside the others goes
    // first (cost -inf); otherwise the one whose removal costs least.
    const double cost = Significance(cands[accepted[a]], current, m) < opt.parameter_sigma
                            ? -1e300 : f.bic - current.bic;
    if (cost < drop_cost) { drop = static_cast<int>(a); drop_cost = cost; drop_fit = f; }
  }
  if (drop < 0) break;
  free.erase(std::find(free.begin(), free.end(), cands[accepted[drop]].block));
  rep.findings.erase(rep.findings.begin() + drop);
  model_name.erase(model_name.begin() + 1 + drop);
  accepted.erase(accepted.begin() + drop);
  current = drop_fit;
  }
  // Parameters of every finding from the final joint fit (an effect's
  // value moves when a later one is accepted beside it).
  for (size_t a = 0; a < accepted.size(); ++a) {
    if (cands[accepted[a]].block == kHarm) m.harm_order = cands[accepted[a]].order;
    const Finding fd = Describe(cands[accepted[a]], m, current);
    rep.findings[a].parameters = fd.parameters;
    rep.findings[a].parameter_std = fd.parameter_std;
  }
  std::string name = "nominal";
  for (size_t k = 1; k < model_name.size(); ++k) name += "+" + model_name[k];
  rep.final_model = {name, current.rms, current.bic, current.chi2};
  const auto z_after = Residuals(m, current.p);
  rep.remaining = Locate(z_after, opt.mismatch_sigma);
  for (size_t k = 0; k < z_before.size(); ++k) {
    rep.residuals.push_back({z_before[k].point, z_before[k].signal, z_before[k].id_a, z_before[k].iq_a,
                             z_before[k].speed_rpm, std::sqrt(z_before[k].z2 / z_before[k].dof),
                             std::sqrt(z_after[k].z2 / z_after[k].dof)});
  }
  const auto ptr = current.p.Ptrs();
  for (size_t k = 0; k < ids.size(); ++k) {
    if (!std::isfinite(ids[k].ld_h) || !std::isfinite(ids[k].id_a)) continue;
    CorrectedPoint cp;
    cp.point = ids[k].point;
    cp.id_a = ids[k].id_a;
    cp.iq_a = ids[k].iq_a;
    m.Inductance(ptr.data(), cp.id_a, cp.iq_a, &cp.ldd_h, &cp.lqq_h, &cp.ldq_h);
    cp.ldd_h_identified = ids[k].ld_h;
    cp.lqq_h_identified = ids[k].lq_h;
    rep.corrected.push_back(cp);
  }
  rep.corrected_data = CorrectedFitData(set, m, current.p, ids);
  // A located region is explained when the accepted findings removed at
  // least 90 % of its chi^2 excess over its degrees of freedom; what stays
  // significant is still listed in `remaining`. A region that the findings
  // made significant (not located before) also leaves the verdict partial:
  // the final model is then wrong somewhere the nominal one was not.
  bool all_explained = true;
  for (const auto& after : rep.remaining) {
    double before_sigma = 0;
    for (const auto& before : rep.mismatches) {
      if (after.signal == before.signal && after.where == before.where) before_sigma = before.significance_sigma;
    }
    if (after.significance_sigma > 0.1 * before_sigma) all_explained = false;
  }
  // Honesty (docs/diagnosis.md): the final model, refitted without one
  // observable class at a time, must predict that class. A located region
  // of the class whose prediction error stays significant means the
  // findings fit the data without being the physics that made them.
  if (!rep.findings.empty()) {
    for (int kind : {kDcKind, kSsKind, kTorqueKind}) {
      const bool has = kind == kDcKind ? !m.dc.empty()
                       : kind == kSsKind ? !m.ss.empty()
                                         : std::any_of(m.ss.begin(), m.ss.end(), [](const SsObs& o) { return o.has_torque; });
      if (!has) continue;
      const FitOut f = Solve(m, current.p, free, kind);
      if (!f.ok) continue;
      HeldOutCheck h;
      h.signal = KindSignal(kind);
      const auto z = Residuals(m, f.p);
      for (const auto& r : RegionStats(z)) {
        if (r.signal == h.signal && r.k > 0) h.significance_sigma = std::max(h.significance_sigma, r.Sigma());
      }
      h.residual_rms = RelativeRmsOf(m, f.p, kind);
      // Without a class, the parameters it pinned down are known less well,
      // so a class whose located mismatch was gross may keep a little of it:
      // the prediction passes below `heldout_sigma`, or when it removes at
      // least 98 % of the class's located significance (e.g. a dead time
      // fitted without the held DC voltages predicts them to 65 sigma of
      // 39566).
      double located = 0;
      for (const auto& mm : rep.mismatches) {
        if (mm.signal == h.signal) located = std::max(located, mm.significance_sigma);
      }
      h.passed = h.significance_sigma < std::max(opt.heldout_sigma, opt.heldout_fraction * located);
      if (!h.passed) all_explained = false;
      rep.held_out.push_back(h);
    }
  }
  if (rep.findings.empty()) {
    rep.verdict = rep.mismatches.empty() ? "no_mismatch" : "unexplained";
  } else {
    rep.verdict = all_explained ? "explained" : "partly_explained";
  }
  // Waveform evidence through the twin (docs/diagnosis.md): replay before
  // and after, with the residual spectrum at multiples of 50 Hz up to
  // +-2.5 kHz (the injection at +-500 Hz, its harmonics, the fundamental).
  if (opt.waveform_replay) {
    for (int f = -50; f <= 50; ++f) rep.spectrum_hz.push_back(50.0 * f);
    rep.waveform_rms_before_a = ReplayResidual(set, m, base.p, m.harm_order, rep.spectrum_hz, &rep.spectrum_before_a);
    rep.waveform_rms_after_a = ReplayResidual(set, m, current.p, m.harm_order, rep.spectrum_hz, &rep.spectrum_after_a);
    auto significant = [&](const std::vector<double>& sp) {
      std::vector<double> sorted = sp, out;
      if (sorted.empty()) return out;
      std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
      const double floor = sorted[sorted.size() / 2];
      for (size_t k = 0; k < sp.size(); ++k) if (sp[k] > 10.0 * floor) out.push_back(rep.spectrum_hz[k]);
      return out;
    };
    rep.significant_hz_before = significant(rep.spectrum_before_a);
    rep.significant_hz_after = significant(rep.spectrum_after_a);
  }
  rep.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return rep;
}

}  // namespace fluxcal::diag
