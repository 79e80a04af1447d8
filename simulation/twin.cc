#include "simulation/twin.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <deque>
#include <fstream>
#include <numbers>
#include <random>
#include <set>
#include <sstream>

#include <Eigen/Dense>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "nlohmann/json.hpp"

namespace fluxcal::sim {
namespace {

constexpr double kPi = std::numbers::pi;
constexpr double kSqrt3 = 1.7320508075688772935;

struct Vec2 {
  double d = 0, q = 0;
};

// Everything the ODE right-hand side needs for one operating point.
struct PlantModel {
  double p[kSaturationParams];   // saturation parameters with psi_pm(T)
  const MagneticModel* map = nullptr;   // replaces p when set
  double map_temperature_c = 25.0, map_psi_shift_wb = 0.0;
  double rs_ohm;
  double r_hf_ohm;
  double hf_corner_rad_s = 2 * kPi * 50.0;   // eddy branch: high-pass corner
  int order = 0;
  double amplitude_h = 0;
  double dead_time_s = 0, dead_time_i_th_a = 1, udc_v = 50, ts_s = 1e-4;
  double u_max_v = 50 / kSqrt3;

  // psi(i, theta) including the spatial-harmonic term amp cos(n theta) i.
  void Flux(double id, double iq, double th, double* pd, double* pq) const {
    if (map) {
      const auto f = map->Flux(id, iq, map_temperature_c);
      *pd = f.psi_d_wb + map_psi_shift_wb;
      *pq = f.psi_q_wb;
    } else {
      SaturationFlux(id, iq, p, pd, pq);
    }
    if (order != 0) {
      const double h = amplitude_h * std::cos(order * th);
      *pd += h * id;
      *pq += h * iq;
    }
  }
  void Jacobian(double id, double iq, double th, double* ldd, double* lqq, double* ldq) const {
    if (map) {
      const auto l = map->Inductance(id, iq, map_temperature_c);
      *ldd = l.ldd_h;
      *lqq = l.lqq_h;
      *ldq = l.ldq_h;
    } else {
      SaturationInductance(id, iq, p, ldd, lqq, ldq);
    }
    if (order != 0) {
      const double h = amplitude_h * std::cos(order * th);
      *ldd += h;
      *lqq += h;
    }
  }
  // i(psi) by Newton from a warm start; converges in 2-3 steps because the
  // model is smooth and the start is the previous sub-step's current.
  Vec2 Current(double psd, double psq, double th, Vec2 guess) const {
    Vec2 i = guess;
    for (int it = 0; it < 20; ++it) {
      double pd, pq, a, b, c;
      Flux(i.d, i.q, th, &pd, &pq);
      Jacobian(i.d, i.q, th, &a, &b, &c);
      const double rd = psd - pd, rq = psq - pq;
      const double det = a * b - c * c;
      const double dd = (b * rd - c * rq) / det, dq = (a * rq - c * rd) / det;
      i.d += dd;
      i.q += dq;
      if (std::abs(dd) + std::abs(dq) < 1e-12 * (1.0 + std::abs(i.d) + std::abs(i.q))) break;
    }
    return i;
  }
};

// Inverter voltage error of an uncompensated dead time, per phase
// -(Td/Ts) Udc tanh(i_x / i_th), common mode removed, in alpha-beta
// (amplitude-invariant Clarke). The paper's eq. (9) is its Fourier series.
void DeadTimeError(const PlantModel& m, double ia, double ib, double ic, double* ua, double* ub) {
  if (m.dead_time_s == 0.0) { *ua = *ub = 0; return; }
  const double k = -(m.dead_time_s / m.ts_s) * m.udc_v;
  const double ea = k * std::tanh(ia / m.dead_time_i_th_a);
  const double eb = k * std::tanh(ib / m.dead_time_i_th_a);
  const double ec = k * std::tanh(ic / m.dead_time_i_th_a);
  *ua = (2 * ea - eb - ec) / 3.0;
  *ub = (eb - ec) / kSqrt3;
}

struct State {
  double psd, psq;       // flux linkage in the true dq frame
  double lpd, lpq;       // low-passed current (eddy branch)
  Vec2 i;                // current consistent with psi (cache)
};

// dx/dt in the true rotor frame: dpsi/dt = u - Rs i - R_hf (i - i_lp) - w J psi.
void Derivative(const PlantModel& m, const State& x, double th, double we, double ual, double ube,
                double* dpsd, double* dpsq, double* dlpd, double* dlpq, Vec2* i_out) {
  const Vec2 i = m.Current(x.psd, x.psq, th, x.i);
  *i_out = i;
  const double c = std::cos(th), s = std::sin(th);
  // Phase currents for the dead-time error.
  const double ial = c * i.d - s * i.q, ibe = s * i.d + c * i.q;
  const double ia = ial, ib = -0.5 * ial + 0.5 * kSqrt3 * ibe, ic = -0.5 * ial - 0.5 * kSqrt3 * ibe;
  double eal, ebe;
  DeadTimeError(m, ia, ib, ic, &eal, &ebe);
  const double ua = ual + eal, ub = ube + ebe;
  const double ud = c * ua + s * ub, uq = -s * ua + c * ub;
  *dpsd = ud - m.rs_ohm * i.d - m.r_hf_ohm * (i.d - x.lpd) + we * x.psq;
  *dpsq = uq - m.rs_ohm * i.q - m.r_hf_ohm * (i.q - x.lpq) - we * x.psd;
  *dlpd = m.hf_corner_rad_s * (i.d - x.lpd);
  *dlpq = m.hf_corner_rad_s * (i.q - x.lpq);
}

// One RK4 step of length h with a held alpha-beta voltage.
void Rk4(const PlantModel& m, State* x, double th0, double we, double h, double ual, double ube) {
  double k1[4], k2[4], k3[4], k4[4];
  Vec2 i;
  auto eval = [&](const State& s, double th, double* k) {
    Derivative(m, s, th, we, ual, ube, &k[0], &k[1], &k[2], &k[3], &i);
  };
  auto add = [&](const State& s, const double* k, double f) {
    State r = s;
    r.psd += f * k[0]; r.psq += f * k[1]; r.lpd += f * k[2]; r.lpq += f * k[3];
    r.i = i;
    return r;
  };
  eval(*x, th0, k1);
  x->i = i;
  eval(add(*x, k1, 0.5 * h), th0 + 0.5 * h * we, k2);
  eval(add(*x, k2, 0.5 * h), th0 + 0.5 * h * we, k3);
  eval(add(*x, k3, h), th0 + h * we, k4);
  x->psd += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0]);
  x->psq += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1]);
  x->lpd += h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2]);
  x->lpq += h / 6 * (k1[3] + 2 * k2[3] + 2 * k3[3] + k4[3]);
  x->i = m.Current(x->psd, x->psq, th0 + h * we, i);
}

double WrapAngle(double a) {
  a = std::fmod(a, 2 * kPi);
  return a < 0 ? a + 2 * kPi : a;
}

struct PointRun {
  io::Waveform wave;
  double mean_id_true = 0, mean_iq_true = 0;
  double mean_ud_cmd = 0, mean_uq_cmd = 0;    // controller frame, fundamental
  double mean_ud_applied = 0, mean_uq_applied = 0;   // true frame, incl. errors
  double mean_torque_nm = 0;
  double avg_id = 0, avg_iq = 0, avg_psd = 0, avg_psq = 0, dpsd = 0, dpsq = 0;
  double mean_id_meas = 0, mean_iq_meas = 0;   // what the bench's sensors report
  bool clipped = false;
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
                  const RunAlignment& align = {}) {
  (void)temperature_c;
  PointRun out;
  const int pp = cfg.motor.pole_pairs;
  const double fs = cfg.drive.f_pwm_hz, ts = 1.0 / fs;
  const int S = std::max(1, cfg.drive.substeps);
  const double h = ts / S;
  const double we = speed_rpm * pp * 2 * kPi / 60.0;
  const size_t n_settle = static_cast<size_t>(std::llround(settle_s * fs));
  const size_t n_rec = static_cast<size_t>(std::llround(record_s * fs));
  const double wi = 2 * kPi * cfg.injection.frequency_hz;
  const double vi = inject ? cfg.injection.amplitude_v : 0.0;
  const size_t period = std::max<size_t>(1, static_cast<size_t>(std::llround(fs / cfg.injection.frequency_hz)));
  const int delay_sub = static_cast<int>(std::llround(cfg.effects.delay_s / h));
  const double dtheta_enc = cfg.sensors.encoder_counts_per_mech_rev > 0
                                  ? 2 * kPi * pp / cfg.sensors.encoder_counts_per_mech_rev
                                  : 0.0;
  std::normal_distribution<double> noise(0.0, cfg.sensors.noise_a);
  std::normal_distribution<double> unoise(0.0, cfg.sensors.udc_noise_v);

  // Nominal controller (what the bench believes): PI with decoupling.
  const double psi_pm_nom = cfg.motor.sat.psi_pm_wb;
  const double kp_d = 2 * kPi * cfg.control.bandwidth_hz * cfg.control.ld_nominal_h;
  const double kp_q = 2 * kPi * cfg.control.bandwidth_hz * cfg.control.lq_nominal_h;
  const double wc_i = 2 * kPi * cfg.control.integral_corner_hz;

  // Start in the steady state of the true machine at the reference.
  State x;
  m.Flux(id_ref, iq_ref, theta0, &x.psd, &x.psq);
  x.lpd = id_ref; x.lpq = iq_ref;
  x.i = Vec2{id_ref, iq_ref};
  double int_d = cfg.motor.rs_ohm * id_ref, int_q = cfg.motor.rs_ohm * iq_ref;

  std::deque<std::pair<double, double>> cmd_hist;   // alpha-beta commands by period
  cmd_hist.push_back({0, 0});
  // Seed the history with the steady-state command so the first periods are
  // not a voltage step.
  {
    double pd, pq;
    m.Flux(id_ref, iq_ref, theta0, &pd, &pq);
    const double ud = m.rs_ohm * id_ref - we * pq, uq = m.rs_ohm * iq_ref + we * pd;
    const double c = std::cos(theta0), s = std::sin(theta0);
    cmd_hist.clear();
    for (int k = 0; k < 4; ++k) cmd_hist.push_back({c * ud - s * uq, s * ud + c * uq});
  }
  std::deque<std::pair<double, double>> fb_hist;   // dq feedback for the moving average
  double fb_sum_d = 0, fb_sum_q = 0;
  const size_t n_total = n_settle + n_rec;
  out.wave.t_s.reserve(n_rec);
  double acc_ud_app = 0, acc_uq_app = 0;
  size_t acc_app = 0;
  std::vector<std::pair<double, double>> cmds(n_total + 2);

  for (size_t k = 0; k < n_total; ++k) {
    const double t = static_cast<double>(k) * ts;
    const double th = theta0 + we * t;
    // --- Sample: sensors.
    const double c = std::cos(th), s = std::sin(th);
    const double ial = c * x.i.d - s * x.i.q, ibe = s * x.i.d + c * x.i.q;
    double ia = ial, ib = -0.5 * ial + 0.5 * kSqrt3 * ibe, ic = -0.5 * ial - 0.5 * kSqrt3 * ibe;
    const double lsb = cfg.sensors.adc_lsb_a;
    auto sense = [&](double i, double g) {
      double v = g * i + noise(*rng);
      if (lsb > 0) v = std::round(v / lsb) * lsb;
      return v;
    };
    const double ma = sense(ia, cfg.effects.gain_a), mb = sense(ib, cfg.effects.gain_b),
                 mc = sense(ic, cfg.effects.gain_c);
    double th_meas = th + cfg.effects.offset_rad;
    // Encoder counts, read to the nearest count (an encoder whose zero is
    // aligned mid-count, as EOL benches calibrate it: no half-count bias).
    if (dtheta_enc > 0) th_meas = std::round(WrapAngle(th_meas) / dtheta_enc) * dtheta_enc;
    th_meas = WrapAngle(th_meas);
    if (align.theta_meas_rad && k >= n_settle && k - n_settle < align.theta_meas_rad->size()) {
      th_meas = WrapAngle((*align.theta_meas_rad)[k - n_settle]);
    }
    // --- Controller on injection-free feedback (moving average over one
    // injection period of the measured dq current).
    const double mal = (2 * ma - mb - mc) / 3.0, mbe = (mb - mc) / kSqrt3;
    const double cm = std::cos(th_meas), sm = std::sin(th_meas);
    const double fd = cm * mal + sm * mbe, fq = -sm * mal + cm * mbe;
    fb_hist.push_back({fd, fq});
    fb_sum_d += fd; fb_sum_q += fq;
    if (fb_hist.size() > period) {
      fb_sum_d -= fb_hist.front().first;
      fb_sum_q -= fb_hist.front().second;
      fb_hist.pop_front();
    }
    const double ifd = fb_sum_d / fb_hist.size(), ifq = fb_sum_q / fb_hist.size();
    const double ed = id_ref - ifd, eq = iq_ref - ifq;
    int_d += kp_d * wc_i * ts * ed;
    int_q += kp_q * wc_i * ts * eq;
    const double ud = kp_d * ed + int_d - we * cfg.control.lq_nominal_h * ifq;
    const double uq = kp_q * eq + int_q + we * (cfg.control.ld_nominal_h * ifd + psi_pm_nom);
    const double inj_c = std::cos(wi * t + align.injection_phase_rad),
                 inj_s = std::sin(wi * t + align.injection_phase_rad);
    // Inverse Park at the angle the rotor will have in the middle of the
    // period the command is applied in (theta + 1.5 w_e Ts): the usual ECU
    // delay compensation, so the dq command is the fundamental voltage the
    // machine sees (up to the hold's sinc gain), as steady_state.csv states.
    const double thc = th_meas + 1.5 * we * ts;
    const double cc = std::cos(thc), sc = std::sin(thc);
    double ual = cc * ud - sc * uq + vi * inj_c, ube = sc * ud + cc * uq + vi * inj_s;
    // Modulator: linear range of space-vector PWM, |u| <= Udc / sqrt(3).
    const double umag = std::hypot(ual, ube);
    if (umag > m.u_max_v) {
      ual *= m.u_max_v / umag;
      ube *= m.u_max_v / umag;
      if (k >= n_settle) out.clipped = true;
    }
    cmds[k] = {ual, ube};
    // What was sent to the modulator, back in the controller's dq frame
    // (differs from the PI output only when the voltage limit clipped).
    const double ud_sent = cc * (ual - vi * inj_c) + sc * (ube - vi * inj_s);
    const double uq_sent = -sc * (ual - vi * inj_c) + cc * (ube - vi * inj_s);
    if (k >= n_settle) {
      const size_t r = k - n_settle;
      out.wave.t_s.push_back(static_cast<double>(r) * ts);
      out.wave.ia_a.push_back(ma);
      out.wave.ib_a.push_back(mb);
      out.wave.ic_a.push_back(mc);
      out.wave.theta_e_rad.push_back(th_meas);
      out.wave.ualpha_ref_v.push_back(ual);
      out.wave.ubeta_ref_v.push_back(ube);
      out.wave.udc_v.push_back(m.udc_v + unoise(*rng));
      out.mean_id_true += x.i.d;
      out.mean_iq_true += x.i.q;
      out.mean_id_meas += fd;
      out.mean_iq_meas += fq;
      out.mean_ud_cmd += ud_sent;
      out.mean_uq_cmd += uq_sent;
      double pd, pq;
      m.Flux(x.i.d, x.i.q, th, &pd, &pq);
      out.mean_torque_nm += 1.5 * pp * (pd * x.i.q - pq * x.i.d);
    }
    // --- Plant over [t_k, t_{k+1}): the command of period k-1 (one PWM
    // period late), shifted further by the sampling_delay effect.
    for (int j = 0; j < S; ++j) {
      const long sub = static_cast<long>(k) * S + j - delay_sub;
      const long per = (sub >= 0 ? sub / S : (sub - S + 1) / S) - 1;
      std::pair<double, double> u = per >= 0 ? cmds[per] : cmd_hist.front();
      const double th_j = th + we * h * j;
      if (k >= n_settle) {
        // Exact mean of the held alpha-beta voltage in the rotating frame
        // over the sub-step: e^{-j theta_mid} sin(y)/y, y = w_e h / 2.
        const double y = 0.5 * we * h;
        const double sinc = std::abs(y) < 1e-12 ? 1.0 : std::sin(y) / y;
        const double cj = sinc * std::cos(th_j + y), sj = sinc * std::sin(th_j + y);
        double eal, ebe;
        const double al = cj * x.i.d - sj * x.i.q, be = sj * x.i.d + cj * x.i.q;
        DeadTimeError(m, al, -0.5 * al + 0.5 * kSqrt3 * be, -0.5 * al - 0.5 * kSqrt3 * be, &eal, &ebe);
        acc_ud_app += cj * (u.first + eal) + sj * (u.second + ebe);
        acc_uq_app += -sj * (u.first + eal) + cj * (u.second + ebe);
        ++acc_app;
      }
      const State before = x;
      Rk4(m, &x, th_j, we, h, u.first, u.second);
      if (k >= n_settle) {
        if (k == n_settle && j == 0) { out.dpsd = -before.psd; out.dpsq = -before.psq; }
        out.avg_id += 0.5 * (before.i.d + x.i.d);
        out.avg_iq += 0.5 * (before.i.q + x.i.q);
        out.avg_psd += 0.5 * (before.psd + x.psd);
        out.avg_psq += 0.5 * (before.psq + x.psq);
      }
    }
  }
  const double nr = static_cast<double>(std::max<size_t>(1, n_rec));
  out.mean_id_true /= nr;
  out.mean_iq_true /= nr;
  out.mean_ud_cmd /= nr;
  out.mean_id_meas /= nr;
  out.mean_iq_meas /= nr;
  out.mean_uq_cmd /= nr;
  out.mean_torque_nm /= nr;
  const double na = static_cast<double>(std::max<size_t>(1, acc_app));
  out.avg_id /= na; out.avg_iq /= na; out.avg_psd /= na; out.avg_psq /= na;
  out.dpsd = (out.dpsd + x.psd) / (nr * ts);
  out.dpsq = (out.dpsq + x.psq) / (nr * ts);
  out.mean_ud_applied = acc_ud_app / std::max<size_t>(1, acc_app);
  out.mean_uq_applied = acc_uq_app / std::max<size_t>(1, acc_app);
  return out;
}

PlantModel MakePlant(const TwinConfig& cfg, double temperature_c) {
  PlantModel m;
  ToArray(cfg.motor.sat, m.p);
  const double psi_pm25 = cfg.effects.psi_pm_wb.value_or(cfg.motor.sat.psi_pm_wb);
  m.p[0] = psi_pm25 * (1.0 + cfg.motor.psi_pm_temp_coeff_per_k * (temperature_c - 25.0));
  if (cfg.effects.cross_saturation != 0.0) m.p[5] = cfg.effects.cross_saturation;
  m.rs_ohm = cfg.effects.rs_ohm.value_or(cfg.motor.rs_ohm);
  if (cfg.magnetics) {
    m.map = cfg.magnetics.get();
    m.map_temperature_c = temperature_c;
    const double map_pm = cfg.magnetics->Flux(0, 0, 25.0).psi_d_wb;
    m.map_psi_shift_wb = cfg.effects.psi_pm_wb ? *cfg.effects.psi_pm_wb - map_pm : 0.0;
    m.p[0] = map_pm + m.map_psi_shift_wb;   // reported psi_pm
  }
  m.r_hf_ohm = cfg.effects.r_hf_ohm;
  m.order = cfg.effects.order;
  m.amplitude_h = cfg.effects.amplitude_h;
  m.dead_time_s = cfg.effects.dead_time_s;
  m.dead_time_i_th_a = cfg.effects.dead_time_i_th_a;
  m.udc_v = cfg.drive.udc_v;
  m.ts_s = 1.0 / cfg.drive.f_pwm_hz;
  m.u_max_v = cfg.drive.udc_v / kSqrt3;
  return m;
}

TruthPoint MakeTruth(const TwinConfig& cfg, const PlantModel& m, const std::string& id, double idt,
                     double iqt, double speed_rpm, double temperature_c, double theta) {
  TruthPoint t;
  t.id = id;
  t.id_true_a = idt;
  t.iq_true_a = iqt;
  t.speed_rpm = speed_rpm;
  t.temperature_c = temperature_c;
  // Locked points: at the rotor angle (matters for spatial harmonics only);
  // rotating points: the angle-dependent term averages out.
  PlantModel mm = m;
  if (speed_rpm != 0.0) mm.order = 0;
  mm.Flux(idt, iqt, theta, &t.psi_d_wb, &t.psi_q_wb);
  mm.Jacobian(idt, iqt, theta, &t.ldd_h, &t.lqq_h, &t.ldq_h);
  t.psi_pm_wb = m.p[0];
  t.ld_app_h = std::abs(idt) > 1e-6 ? (t.psi_d_wb - m.p[0]) / idt : t.ldd_h;
  t.lq_app_h = std::abs(iqt) > 1e-6 ? t.psi_q_wb / iqt : t.lqq_h;
  t.torque_nm = 1.5 * cfg.motor.pole_pairs * (t.psi_d_wb * iqt - t.psi_q_wb * idt);
  return t;
}

}  // namespace

FluxLinkage AnalyticMotor::Flux(double id_a, double iq_a, double temperature_c) const {
  double p[kSaturationParams];
  ToArray(p_.sat, p);
  p[0] *= 1.0 + p_.psi_pm_temp_coeff_per_k * (temperature_c - 25.0);
  FluxLinkage f;
  SaturationFlux(id_a, iq_a, p, &f.psi_d_wb, &f.psi_q_wb);
  return f;
}

DifferentialInductance AnalyticMotor::Inductance(double id_a, double iq_a, double) const {
  double p[kSaturationParams];
  ToArray(p_.sat, p);
  DifferentialInductance l;
  SaturationInductance(id_a, iq_a, p, &l.ldd_h, &l.lqq_h, &l.ldq_h);
  return l;
}

absl::Status ParseEffects(const std::string& spec, Effects* e, double* noise_a) {
  if (spec.empty()) return absl::OkStatus();
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
    if (k == "dead_time_s") e->dead_time_s = v;
    else if (k == "dead_time_i_th_a") e->dead_time_i_th_a = v;
    else if (k == "rs_ohm") e->rs_ohm = v;
    else if (k == "r_hf_ohm") e->r_hf_ohm = v;
    else if (k == "offset_rad") e->offset_rad = v;
    else if (k == "gain_a") e->gain_a = v;
    else if (k == "gain_b") e->gain_b = v;
    else if (k == "gain_c") e->gain_c = v;
    else if (k == "psi_pm_wb") e->psi_pm_wb = v;
    else if (k == "delay_s") e->delay_s = v;
    else if (k == "order") e->order = static_cast<int>(v);
    else if (k == "amplitude_h") e->amplitude_h = v;
    else if (k == "cross_saturation") e->cross_saturation = v;
    else if (k == "noise_a" && noise_a != nullptr) *noise_a = v;
    else {
      return absl::InvalidArgumentError(absl::StrCat(
          "flag --effects: unknown key '", k,
          "' (known: dead_time_s, dead_time_i_th_a, rs_ohm, r_hf_ohm, offset_rad, gain_a, gain_b, "
          "gain_c, psi_pm_wb, delay_s, order, amplitude_h, cross_saturation, noise_a)"));
    }
  }
  return absl::OkStatus();
}

std::vector<std::string> ActiveEffectNames(const Effects& e) {
  std::vector<std::string> out;
  if (e.dead_time_s != 0) out.push_back("dead_time");
  if (e.cross_saturation != 0) out.push_back("cross_saturation");
  if (e.rs_ohm) out.push_back("stator_resistance");
  if (e.r_hf_ohm != 0) out.push_back("hf_resistance");
  if (e.offset_rad != 0) out.push_back("position_offset");
  if (e.gain_a != 1 || e.gain_b != 1 || e.gain_c != 1) out.push_back("current_sensor_gain");
  if (e.psi_pm_wb) out.push_back("magnet_temperature");
  if (e.delay_s != 0) out.push_back("sampling_delay");
  if (e.order != 0 && e.amplitude_h != 0) out.push_back("spatial_harmonics");
  return out;
}

Plan DefaultPlan() {
  Plan plan;
  int k = 0;
  for (int a = 0; a <= 5; ++a) {
    for (int b = 0; b <= 5; ++b) {
      PlanPoint p;
      p.id = absl::StrFormat("p%03d", k);
      p.id_ref_a = -100.0 + 20.0 * a;
      p.iq_ref_a = 20.0 * b;
      // Spread the locked angles over the electrical revolution (golden
      // angle) so that angle-dependent effects are observable.
      p.theta_e_rad = std::fmod(0.3 + 2.39996322972865332 * k, 2 * kPi);
      plan.points.push_back(p);
      ++k;
    }
  }
  const double rot[][3] = {{-20, 40, 200}, {-40, 60, 500}, {-20, 40, 1000}, {-60, 80, 750}};
  for (const auto& r : rot) {
    PlanPoint p;
    p.id = absl::StrFormat("p%03d", k++);
    p.id_ref_a = r[0];
    p.iq_ref_a = r[1];
    p.speed_rpm = r[2];
    p.theta_e_rad = 0.5;
    plan.points.push_back(p);
  }
  const double ss[][3] = {{0, 40, 1000}, {-20, 60, 1000}, {-40, 80, 1500}, {-20, 100, 1500},
                          {-60, 60, 2000}, {0, 20, 2000}, {-80, 100, 1500}, {-40, 40, 1200}};
  for (const auto& r : ss) plan.steady_state.push_back({r[0], r[1], r[2], 25.0});
  return plan;
}

absl::StatusOr<SimulationResult> Simulate(const TwinConfig& cfg, const Plan& plan) {
  if (!io::IsValidSerial(cfg.serial)) {
    return absl::InvalidArgumentError(absl::StrCat("field 'serial': illegal serial '", cfg.serial, "'"));
  }
  SimulationResult res;
  io::RecordingSet& set = res.set;
  io::Manifest& mf = set.manifest;
  mf.serial = cfg.serial;
  mf.motor.pole_pairs = cfg.motor.pole_pairs;
  mf.motor.rs_ohm = cfg.motor.rs_ohm;               // nominal: what the bench believes
  mf.motor.psi_pm_wb = cfg.motor.sat.psi_pm_wb;
  mf.drive.udc_v = cfg.drive.udc_v;
  mf.drive.f_pwm_hz = cfg.drive.f_pwm_hz;
  mf.drive.f_sample_hz = cfg.drive.f_pwm_hz;
  mf.drive.dead_time_s = cfg.drive.nominal_dead_time_s;
  mf.drive.dead_time_compensated = true;
  mf.injection = io::InjectionInfo{"rotating", cfg.injection.amplitude_v, cfg.injection.frequency_hz};
  std::mt19937_64 rng(cfg.seed);
  for (const auto& pt : plan.points) {
    const PlantModel m = MakePlant(cfg, pt.temperature_c);
    PointRun run = RunPoint(cfg, m, pt.id_ref_a, pt.iq_ref_a, pt.speed_rpm, pt.theta_e_rad,
                            pt.temperature_c, true, plan.settle_s, plan.record_s, &rng);
    res.clipped |= run.clipped;
    io::PointSpec ps;
    ps.id = pt.id;
    ps.file = absl::StrCat("points/", pt.id, ".csv");
    ps.id_ref_a = pt.id_ref_a;
    ps.iq_ref_a = pt.iq_ref_a;
    ps.speed_rpm = pt.speed_rpm;
    ps.temperature_c = pt.temperature_c;
    mf.points.push_back(ps);
    set.waveforms.push_back(std::move(run.wave));
    res.truth_points.push_back(MakeTruth(cfg, m, pt.id, run.mean_id_true, run.mean_iq_true,
                                         pt.speed_rpm, pt.temperature_c, pt.theta_e_rad));
  }
  if (!plan.steady_state.empty()) {
    mf.steady_state = "steady_state.csv";
    std::normal_distribution<double> tnoise(0.0, 0.01);
    for (const auto& ss : plan.steady_state) {
      const PlantModel m = MakePlant(cfg, ss.temperature_c);
      PointRun run = RunPoint(cfg, m, ss.id_ref_a, ss.iq_ref_a, ss.speed_rpm, 0.2,
                              ss.temperature_c, false, plan.settle_s, 0.05, &rng);
      io::SteadyStateRow row;
      // The bench reports the measured mean current (it differs from the
      // reference when the voltage limit is hit or a sensor is off).
      row.id_a = run.mean_id_meas;
      row.iq_a = run.mean_iq_meas;
      row.speed_rpm = ss.speed_rpm;
      row.ud_ref_v = run.mean_ud_cmd;
      row.uq_ref_v = run.mean_uq_cmd;
      row.torque_nm = run.mean_torque_nm + tnoise(rng);
      row.temperature_c = ss.temperature_c;
      set.steady_state.push_back(row);
      res.truth_steady_state.push_back(MakeTruth(cfg, m, "", run.mean_id_true, run.mean_iq_true,
                                                 ss.speed_rpm, ss.temperature_c, 0.0));
      res.truth_steady_state.back().applied_ud_v = run.mean_ud_applied;
      res.truth_steady_state.back().applied_uq_v = run.mean_uq_applied;
      auto& tb = res.truth_steady_state.back();
      tb.avg_id_a = run.avg_id; tb.avg_iq_a = run.avg_iq;
      tb.avg_psi_d_wb = run.avg_psd; tb.avg_psi_q_wb = run.avg_psq;
      tb.dpsi_d_dt = run.dpsd; tb.dpsi_q_dt = run.dpsq;
    }
  }
  return res;
}

std::string TruthJson(const TwinConfig& cfg, const SimulationResult& r) {
  using nlohmann::json;
  json j;
  j["format"] = "fluxcal.truth.v1";
  j["serial"] = cfg.serial;
  j["seed"] = cfg.seed;
  json eff = json::array();
  const Effects& e = cfg.effects;
  for (const auto& name : ActiveEffectNames(e)) {
    json p = json::object();
    if (name == "dead_time") p = {{"dead_time_s", e.dead_time_s}, {"i_th_a", e.dead_time_i_th_a}};
    if (name == "cross_saturation") p = {{"strength_h", e.cross_saturation}};
    if (name == "stator_resistance") p = {{"rs_ohm", *e.rs_ohm}};
    if (name == "hf_resistance") p = {{"r_hf_ohm", e.r_hf_ohm}};
    if (name == "position_offset") p = {{"offset_rad", e.offset_rad}};
    if (name == "current_sensor_gain") p = {{"gain_a", e.gain_a}, {"gain_b", e.gain_b}, {"gain_c", e.gain_c}};
    if (name == "magnet_temperature") p = {{"psi_pm_wb", *e.psi_pm_wb}};
    if (name == "sampling_delay") p = {{"delay_s", e.delay_s}};
    if (name == "spatial_harmonics") p = {{"order", e.order}, {"amplitude_h", e.amplitude_h}};
    eff.push_back({{"effect", name}, {"parameters", p}});
  }
  j["concealed_effects"] = eff;
  j["expected_verdict"] = eff.empty() ? "no_mismatch" : "explained";
  j["motor"] = {{"pole_pairs", cfg.motor.pole_pairs}, {"rs_ohm", e.rs_ohm.value_or(cfg.motor.rs_ohm)},
                {"psi_pm_wb", e.psi_pm_wb.value_or(cfg.motor.sat.psi_pm_wb)},
                {"ld0_h", cfg.motor.sat.ld0_h}, {"lq0_h", cfg.motor.sat.lq0_h},
                {"id_sat_a", cfg.motor.sat.id_sat_a}, {"iq_sat_a", cfg.motor.sat.iq_sat_a},
                {"g_cross_h", e.cross_saturation != 0 ? e.cross_saturation : cfg.motor.sat.g_cross_h},
                {"ix_a", cfg.motor.sat.ix_a}};
  auto pt = [](const TruthPoint& t) {
    json o = {{"id_true_a", t.id_true_a}, {"iq_true_a", t.iq_true_a}, {"speed_rpm", t.speed_rpm},
              {"psi_d_wb", t.psi_d_wb}, {"psi_q_wb", t.psi_q_wb}, {"ldd_h", t.ldd_h},
              {"lqq_h", t.lqq_h}, {"ldq_h", t.ldq_h}, {"ld_app_h", t.ld_app_h},
              {"lq_app_h", t.lq_app_h}, {"torque_nm", t.torque_nm}, {"psi_pm_wb", t.psi_pm_wb},
              {"temperature_c", t.temperature_c}};
    if (!t.id.empty()) o["id"] = t.id;
    return o;
  };
  j["points"] = json::array();
  for (const auto& t : r.truth_points) j["points"].push_back(pt(t));
  j["steady_state"] = json::array();
  for (const auto& t : r.truth_steady_state) j["steady_state"].push_back(pt(t));
  return j.dump(2) + "\n";
}

namespace {

absl::StatusOr<nlohmann::json> ReadJsonFile(const std::string& path) {
  std::ifstream f(path);
  if (!f) return absl::NotFoundError(absl::StrCat(path, ": file not found"));
  std::stringstream ss;
  ss << f.rdbuf();
  try {
    return nlohmann::json::parse(ss.str());
  } catch (const nlohmann::json::parse_error& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": field '(json)': ", e.what()));
  }
}

// Reads known numeric keys of an object; unknown keys are errors.
absl::Status ReadNumbers(const std::string& path, const std::string& prefix, const nlohmann::json& o,
                         const std::map<std::string, double*>& fields) {
  if (!o.is_object()) return absl::InvalidArgumentError(absl::StrCat(path, ": field '", prefix, "': expected an object"));
  for (const auto& [k, v] : o.items()) {
    auto it = fields.find(k);
    if (it == fields.end()) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": field '", prefix, k, "': unknown key"));
    }
    if (!v.is_number()) {
      return absl::InvalidArgumentError(absl::StrCat(path, ": field '", prefix, k, "': expected a number"));
    }
    *it->second = v.get<double>();
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status LoadMotorJson(const std::string& path, TwinConfig* cfg) {
  auto j = ReadJsonFile(path);
  if (!j.ok()) return j.status();
  if (!j->is_object()) return absl::InvalidArgumentError(absl::StrCat(path, ": expected an object"));
  double pp = cfg->motor.pole_pairs;
  for (const auto& [k, v] : j->items()) {
    absl::Status st;
    if (k == "serial") {
      if (!v.is_string()) return absl::InvalidArgumentError(absl::StrCat(path, ": field 'serial': expected a string"));
      cfg->serial = v.get<std::string>();
    } else if (k == "motor") {
      st = ReadNumbers(path, "motor.", v,
                       {{"pole_pairs", &pp}, {"rs_ohm", &cfg->motor.rs_ohm},
                        {"psi_pm_wb", &cfg->motor.sat.psi_pm_wb}, {"ld0_h", &cfg->motor.sat.ld0_h},
                        {"lq0_h", &cfg->motor.sat.lq0_h}, {"id_sat_a", &cfg->motor.sat.id_sat_a},
                        {"iq_sat_a", &cfg->motor.sat.iq_sat_a}, {"g_cross_h", &cfg->motor.sat.g_cross_h},
                        {"ix_a", &cfg->motor.sat.ix_a},
                        {"psi_pm_temp_coeff_per_k", &cfg->motor.psi_pm_temp_coeff_per_k}});
    } else if (k == "drive") {
      st = ReadNumbers(path, "drive.", v,
                       {{"udc_v", &cfg->drive.udc_v}, {"f_pwm_hz", &cfg->drive.f_pwm_hz},
                        {"nominal_dead_time_s", &cfg->drive.nominal_dead_time_s}});
    } else if (k == "sensors") {
      double counts = cfg->sensors.encoder_counts_per_mech_rev;
      st = ReadNumbers(path, "sensors.", v,
                       {{"noise_a", &cfg->sensors.noise_a}, {"adc_lsb_a", &cfg->sensors.adc_lsb_a},
                        {"encoder_counts_per_mech_rev", &counts}, {"udc_noise_v", &cfg->sensors.udc_noise_v}});
      cfg->sensors.encoder_counts_per_mech_rev = static_cast<int>(counts);
    } else if (k == "control") {
      st = ReadNumbers(path, "control.", v,
                       {{"bandwidth_hz", &cfg->control.bandwidth_hz},
                        {"integral_corner_hz", &cfg->control.integral_corner_hz},
                        {"ld_nominal_h", &cfg->control.ld_nominal_h},
                        {"lq_nominal_h", &cfg->control.lq_nominal_h}});
    } else if (k == "injection") {
      st = ReadNumbers(path, "injection.", v,
                       {{"amplitude_v", &cfg->injection.amplitude_v},
                        {"frequency_hz", &cfg->injection.frequency_hz}});
    } else {
      return absl::InvalidArgumentError(absl::StrCat(path, ": field '", k, "': unknown key"));
    }
    if (!st.ok()) return st;
  }
  if (pp < 1 || pp != std::floor(pp)) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": field 'motor.pole_pairs': must be a positive integer"));
  }
  cfg->motor.pole_pairs = static_cast<int>(pp);
  return absl::OkStatus();
}

absl::StatusOr<Plan> LoadPlanJson(const std::string& path) {
  auto j = ReadJsonFile(path);
  if (!j.ok()) return j.status();
  Plan plan;
  plan.points.clear();
  if (!j->is_object()) return absl::InvalidArgumentError(absl::StrCat(path, ": expected an object"));
  for (const auto& [k, v] : j->items()) {
    if (k == "settle_s" || k == "record_s") {
      if (!v.is_number()) return absl::InvalidArgumentError(absl::StrCat(path, ": field '", k, "': expected a number"));
      (k == "settle_s" ? plan.settle_s : plan.record_s) = v.get<double>();
    } else if (k == "points") {
      if (!v.is_array()) return absl::InvalidArgumentError(absl::StrCat(path, ": field 'points': expected an array"));
      for (size_t n = 0; n < v.size(); ++n) {
        PlanPoint p;
        p.id = absl::StrFormat("p%03d", n);
        const auto& o = v[n];
        if (o.contains("id")) {
          if (!o["id"].is_string()) return absl::InvalidArgumentError(absl::StrCat(path, ": field 'points[", n, "].id': expected a string"));
          p.id = o["id"].get<std::string>();
        }
        nlohmann::json rest = o;
        rest.erase("id");
        auto st = ReadNumbers(path, absl::StrCat("points[", n, "]."), rest,
                              {{"id_ref_a", &p.id_ref_a}, {"iq_ref_a", &p.iq_ref_a},
                               {"speed_rpm", &p.speed_rpm}, {"theta_e_rad", &p.theta_e_rad},
                               {"temperature_c", &p.temperature_c}});
        if (!st.ok()) return st;
        plan.points.push_back(p);
      }
    } else if (k == "steady_state") {
      if (!v.is_array()) return absl::InvalidArgumentError(absl::StrCat(path, ": field 'steady_state': expected an array"));
      for (size_t n = 0; n < v.size(); ++n) {
        PlanSteadyState s;
        auto st = ReadNumbers(path, absl::StrCat("steady_state[", n, "]."), v[n],
                              {{"id_ref_a", &s.id_ref_a}, {"iq_ref_a", &s.iq_ref_a},
                               {"speed_rpm", &s.speed_rpm}, {"temperature_c", &s.temperature_c}});
        if (!st.ok()) return st;
        plan.steady_state.push_back(s);
      }
    } else {
      return absl::InvalidArgumentError(absl::StrCat(path, ": field '", k, "': unknown key"));
    }
  }
  return plan;
}

// The plant both replays drive: `model` as the magnetics, the effects the
// caller wants included, the recording's drive.
PlantModel ReplayPlant(const MagneticModel& model, double temperature_c, double rs_ohm, const Effects& e,
                       double udc_v, double ts_s, double u_max_v) {
  PlantModel m;
  ToArray(SaturationParams{}, m.p);
  m.map = &model;
  m.map_temperature_c = temperature_c;
  m.rs_ohm = rs_ohm;
  m.r_hf_ohm = e.r_hf_ohm;
  m.order = e.order;
  m.amplitude_h = e.amplitude_h;
  m.dead_time_s = e.dead_time_s;
  m.dead_time_i_th_a = e.dead_time_i_th_a;
  m.udc_v = udc_v;
  m.ts_s = ts_s;
  m.u_max_v = u_max_v;
  return m;
}

absl::StatusOr<std::vector<ReplayPoint>> ReplayOpenLoop(const io::RecordingSet& set, const MagneticModel& model,
                                                        const ReplayOptions& opt) {
  const auto& mf = set.manifest;
  const double fs = mf.drive.f_sample_hz;
  const double f_pwm = mf.drive.f_pwm_hz.value_or(fs);
  if (std::abs(f_pwm - fs) > 1e-9 * fs) {
    return absl::UnimplementedError("replay: f_pwm_hz must equal f_sample_hz");
  }
  const double ts = 1.0 / fs;
  const int S = std::max(1, opt.substeps);
  const double h = ts / S;
  std::vector<ReplayPoint> out;
  for (size_t p = 0; p < set.waveforms.size(); ++p) {
    const auto& w = set.waveforms[p];
    const size_t n = w.size();
    // The recorded commands are already limited: no modulator limit.
    const PlantModel m = ReplayPlant(model, mf.points[p].temperature_c.value_or(25.0), opt.rs_ohm, opt.effects,
                                     mf.drive.udc_v.value_or(50.0), ts, 1e9);
    auto true_theta = [&](size_t k) { return w.theta_e_rad[k] - opt.effects.offset_rad; };
    // Unwrapped angle and its per-sample rate (the plant needs w_e).
    std::vector<double> th(n);
    th[0] = true_theta(0);
    for (size_t k = 1; k < n; ++k) {
      double d = std::remainder(true_theta(k) - true_theta(k - 1), 2 * kPi);
      th[k] = th[k - 1] + d;
    }
    // Initial state from the current measured at sample 1 (sensor gains
    // undone): the interval before it holds row 0's command, the first one
    // whose value is recorded.
    if (n < 3) return absl::InvalidArgumentError("replay: too few samples");
    const double ia = w.ia_a[1] / opt.effects.gain_a, ib = w.ib_a[1] / opt.effects.gain_b,
                 ic = w.ic_a[1] / opt.effects.gain_c;
    const double al = (2 * ia - ib - ic) / 3.0, be = (ib - ic) / kSqrt3;
    const double c0 = std::cos(th[1]), s0 = std::sin(th[1]);
    State x;
    x.i = Vec2{c0 * al + s0 * be, -s0 * al + c0 * be};
    m.Flux(x.i.d, x.i.q, th[1], &x.psd, &x.psq);
    x.lpd = x.i.d;
    x.lpq = x.i.q;
    ReplayPoint rp;
    rp.point = mf.points[p].id;
    rp.ia_a.push_back(w.ia_a[0]);   // sample 0 is not simulated
    rp.ib_a.push_back(w.ib_a[0]);
    rp.ic_a.push_back(w.ic_a[0]);
    double se = 0;
    for (size_t k = 1; k < n; ++k) {
      const double c = std::cos(th[k]), s = std::sin(th[k]);
      const double a = c * x.i.d - s * x.i.q, b = s * x.i.d + c * x.i.q;
      const double sa = opt.effects.gain_a * a;
      const double sb = opt.effects.gain_b * (-0.5 * a + 0.5 * kSqrt3 * b);
      const double sc = opt.effects.gain_c * (-0.5 * a - 0.5 * kSqrt3 * b);
      rp.ia_a.push_back(sa);
      rp.ib_a.push_back(sb);
      rp.ic_a.push_back(sc);
      se += (sa - w.ia_a[k]) * (sa - w.ia_a[k]) + (sb - w.ib_a[k]) * (sb - w.ib_a[k]) +
            (sc - w.ic_a[k]) * (sc - w.ic_a[k]);
      if (k + 1 == n) break;
      const double we = (th[k + 1] - th[k]) / ts;
      // Interval [t_k, t_k+1) holds the command of row k-1 (row 0 for the
      // first interval, whose predecessor was not recorded), shifted by the
      // sampling_delay effect in sub-steps.
      const int delay_sub = static_cast<int>(std::llround(opt.effects.delay_s / h));
      for (int j = 0; j < S; ++j) {
        const long sub = static_cast<long>(k) * S + j - delay_sub;
        long row = (sub >= 0 ? sub / S : (sub - S + 1) / S) - 1;
        row = std::clamp<long>(row, 0, static_cast<long>(n) - 1);   // before row 0: row 0
        Rk4(m, &x, th[k] + we * h * j, we, h, w.ualpha_ref_v[row], w.ubeta_ref_v[row]);
      }
    }
    rp.residual_rms_a = std::sqrt(se / (3.0 * (n - 1)));
    out.push_back(std::move(rp));
  }
  return out;
}

// The injection phasor V of the recorded command u = V e^{j w_i t} + (c0 +
// c1 tau) e^{j theta}: complex least squares over the record with the
// fundamental (rotating with the recorded angle, drifting linearly) as two
// more regressors, so the fundamental does not leak into V at speed. (What
// the controller itself adds at w_i is not separable here; ReplayClosedLoop
// refines the phase against its own simulated command.)
std::complex<double> CommandedInjection(const io::Waveform& w, double wi, double ts) {
  using C = std::complex<double>;
  const size_t n = w.size();
  const double t_mid = 0.5 * static_cast<double>(n - 1) * ts;
  Eigen::Matrix3cd G = Eigen::Matrix3cd::Zero();
  Eigen::Vector3cd h = Eigen::Vector3cd::Zero();
  for (size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * ts;
    const C e = std::polar(1.0, w.theta_e_rad[k]);
    const Eigen::Vector3cd b(std::polar(1.0, wi * t), e, (t - t_mid) / std::max(t_mid, ts) * e);
    G.noalias() += b.conjugate() * b.transpose();
    h.noalias() += b.conjugate() * C(w.ualpha_ref_v[k], w.ubeta_ref_v[k]);
  }
  return G.ldlt().solve(h)(0);
}

absl::StatusOr<std::vector<ReplayPoint>> ReplayClosedLoop(const io::RecordingSet& set, const MagneticModel& model,
                                                          const ClosedLoopReplayOptions& opt) {
  const auto& mf = set.manifest;
  const double fs = mf.drive.f_sample_hz;
  if (std::abs(mf.drive.f_pwm_hz.value_or(fs) - fs) > 1e-9 * fs) {
    return absl::UnimplementedError("replay: f_pwm_hz must equal f_sample_hz");
  }
  if (!mf.injection) return absl::InvalidArgumentError("field 'injection': closed-loop replay needs it");
  const double ts = 1.0 / fs;
  // The bench as the manifest declares it, with ideal sensors (the recorded
  // angle is fed to the controller directly) and the assumed controller.
  TwinConfig cfg;
  cfg.motor.pole_pairs = mf.motor.pole_pairs;
  cfg.motor.rs_ohm = opt.rs_ohm;
  cfg.motor.sat.psi_pm_wb = mf.motor.psi_pm_wb.value_or(cfg.motor.sat.psi_pm_wb);   // decoupling
  cfg.drive.udc_v = mf.drive.udc_v.value_or(cfg.drive.udc_v);
  cfg.drive.f_pwm_hz = fs;
  cfg.drive.substeps = opt.substeps;
  cfg.sensors.noise_a = 0.0;
  cfg.sensors.udc_noise_v = 0.0;
  cfg.sensors.adc_lsb_a = 0.0;
  cfg.sensors.encoder_counts_per_mech_rev = 0;
  cfg.control = opt.control;
  cfg.injection.amplitude_v = mf.injection->amplitude_v;
  cfg.injection.frequency_hz = mf.injection->frequency_hz;
  cfg.effects = opt.effects;
  const double wi = 2 * kPi * cfg.injection.frequency_hz;
  std::mt19937_64 rng(1);
  std::vector<ReplayPoint> out;
  for (size_t p = 0; p < set.waveforms.size(); ++p) {
    const auto& w = set.waveforms[p];
    const auto& pt = mf.points[p];
    const size_t n = w.size();
    if (n < 3) return absl::InvalidArgumentError("replay: too few samples");
    const PlantModel m = ReplayPlant(model, pt.temperature_c.value_or(25.0), opt.rs_ohm, opt.effects,
                                     cfg.drive.udc_v, ts, cfg.drive.udc_v / kSqrt3);
    // Align the run's record window with the recording: the plant's angle
    // follows the recorded one less the offset effect, and the
    // injection has the recorded phase at its first sample.
    // The plant's angle: the least-squares line through the unwrapped
    // recorded angle (an encoder's quantisation averages out along it).
    double sx = 0, sy = 0, sxx = 0, sxy = 0, unwrapped = w.theta_e_rad[0];
    for (size_t k = 0; k < n; ++k) {
      if (k > 0) unwrapped += std::remainder(w.theta_e_rad[k] - w.theta_e_rad[k - 1], 2 * kPi);
      const double x = static_cast<double>(k);
      sx += x; sy += unwrapped; sxx += x * x; sxy += x * unwrapped;
    }
    const double nn = static_cast<double>(n);
    const double slope = (nn * sxy - sx * sy) / (nn * sxx - sx * sx);   // rad per sample
    const double intercept = (sy - slope * sx) / nn;
    const double we = slope * fs;
    const double speed_rpm = we * 60.0 / (2 * kPi * cfg.motor.pole_pairs);
    const size_t n_settle = static_cast<size_t>(std::llround(opt.settle_s * fs));
    const double settle_s = static_cast<double>(n_settle) * ts;
    const double theta0 = intercept - opt.effects.offset_rad - we * settle_s;
    // The command's component at w_i is the injection plus what the
    // controller adds there (at speed its injection-free feedback keeps a
    // little HF ripple), so the phase is refined once: run, compare the
    // simulated command's w_i phasor with the recorded one, shift.
    const std::complex<double> v_rec = CommandedInjection(w, wi, ts);
    RunAlignment align;
    align.injection_phase_rad = std::arg(v_rec) - wi * settle_s;
    align.theta_meas_rad = &w.theta_e_rad;
    auto run_once = [&] {
      return RunPoint(cfg, m, pt.id_ref_a, pt.iq_ref_a, speed_rpm, theta0, m.map_temperature_c, true, settle_s,
                      static_cast<double>(n) * ts, &rng, align);
    };
    PointRun run = run_once();
    if (run.wave.size() == n) {
      align.injection_phase_rad += std::arg(v_rec / CommandedInjection(run.wave, wi, ts));
      run = run_once();
    }
    ReplayPoint rp;
    rp.point = pt.id;
    rp.ia_a = std::move(run.wave.ia_a);
    rp.ib_a = std::move(run.wave.ib_a);
    rp.ic_a = std::move(run.wave.ic_a);
    if (rp.ia_a.size() != n) return absl::InternalError("replay: record window length mismatch");
    double se = 0;
    for (size_t k = 0; k < n; ++k) {
      se += (rp.ia_a[k] - w.ia_a[k]) * (rp.ia_a[k] - w.ia_a[k]) + (rp.ib_a[k] - w.ib_a[k]) * (rp.ib_a[k] - w.ib_a[k]) +
            (rp.ic_a[k] - w.ic_a[k]) * (rp.ic_a[k] - w.ic_a[k]);
    }
    rp.residual_rms_a = std::sqrt(se / (3.0 * n));
    out.push_back(std::move(rp));
  }
  return out;
}

MotorParams PerturbForProduction(const MotorParams& nominal, uint64_t seed) {
  std::mt19937_64 rng(seed * 0x9E3779B97F4A7C15ull + 12345);
  std::normal_distribution<double> n(0.0, 1.0);
  MotorParams m = nominal;
  // Typical EOL spread: magnets +-1.5 %, lamination/air gap +-2 % on
  // inductance, saturation onset +-3 %, winding resistance +-2 %.
  m.sat.psi_pm_wb *= 1.0 + 0.015 * n(rng);
  m.sat.ld0_h *= 1.0 + 0.02 * n(rng);
  m.sat.lq0_h *= 1.0 + 0.02 * n(rng);
  m.sat.id_sat_a *= 1.0 + 0.03 * n(rng);
  m.sat.iq_sat_a *= 1.0 + 0.03 * n(rng);
  m.rs_ohm *= 1.0 + 0.02 * n(rng);
  return m;
}

}  // namespace fluxcal::sim
