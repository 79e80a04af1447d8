#include "simulation/bench.h"

#include <algorithm>
#include <cmath>
#include <deque>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "physics/delay.h"
#include "physics/torque.h"
#include "simulation/catalogue/catalogue_effect.h"

namespace fluxcal::sim {

PointRun RunPoint(const TwinConfig& cfg, const PlantModel& m, double id_ref, double iq_ref,
                  double speed_rpm, double theta0, double temperature_c, bool inject,
                  double settle_s, double record_s, std::mt19937_64* rng,
                  const RunAlignment& align) {
  (void)temperature_c;
  PointRun out;
  const int pp = cfg.motor.pole_pairs;
  const double fs = cfg.drive.f_pwm_hz, ts = 1.0 / fs;
  const int S = std::max(1, cfg.drive.substeps);
  const double h = ts / S;
  const double we = RpmToElectricalRadS(speed_rpm, pp);
  const size_t n_settle = static_cast<size_t>(std::llround(settle_s * fs));
  const size_t n_rec = static_cast<size_t>(std::llround(record_s * fs));
  const double wi = 2 * kPi * cfg.injection.frequency_hz;
  const double vi = inject ? cfg.injection.amplitude_v : 0.0;
  const size_t period = std::max<size_t>(1, static_cast<size_t>(std::llround(fs / cfg.injection.frequency_hz)));
  // The sampling_delay effect as whole sub-steps and a fraction of one: a
  // delay of 8 us on 10 us sub-steps was applied as 10 us, and 3 us as
  // none, while the truth file stated the value asked for. Within a
  // sub-step whose command changes, the command before holds for the
  // fraction (the plant integrated in two parts, as the replays do,
  // replay.cc).
  const double delay_subs = std::max(0.0, cfg.effects.delay_s) / h;
  int delay_sub = static_cast<int>(std::llround(delay_subs));
  double delay_frac = 0.0;
  if (std::abs(delay_subs - delay_sub) > 1e-9) {
    delay_sub = static_cast<int>(std::floor(delay_subs));
    delay_frac = delay_subs - delay_sub;
  }
  const double dtheta_enc = cfg.sensors.encoder_counts_per_mech_rev > 0
                                  ? 2 * kPi * pp / cfg.sensors.encoder_counts_per_mech_rev
                                  : 0.0;
  std::normal_distribution<double> noise(0.0, cfg.sensors.noise_a);
  std::normal_distribution<double> unoise(0.0, cfg.sensors.udc_noise_v);

  // Nominal controller (what the bench believes): PI with decoupling.
  const double psi_pm_nom = cfg.motor.sat.psi_pm_wb;
  double l_ctrl_d = cfg.control.ld_nominal_h, l_ctrl_q = cfg.control.lq_nominal_h;
  if (cfg.control.gain_scheduled) {
    double ldd, lqq, ldq;
    m.Jacobian(id_ref, iq_ref, theta0, &ldd, &lqq, &ldq);
    if (std::isfinite(ldd)) l_ctrl_d = std::max(ldd, 0.1 * cfg.control.ld_nominal_h);
    if (std::isfinite(lqq)) l_ctrl_q = std::max(lqq, 0.1 * cfg.control.lq_nominal_h);
  }
  const double kp_d = 2 * kPi * cfg.control.bandwidth_hz * l_ctrl_d;
  const double kp_q = 2 * kPi * cfg.control.bandwidth_hz * l_ctrl_q;
  const double wc_i = 2 * kPi * cfg.control.integral_corner_hz;

  // Start in the steady state of the true machine at the reference, on
  // the injection's flux orbit: the injection has been running. Started at
  // the orbit's centre, the first period would integrate the rotating HF
  // voltage from there and leave the whole orbit offset by its radius
  // V / w_i (int_0^t V e^{j w s} ds = (V / j w)(e^{j w t} - 1)), a DC flux
  // step that the current loop removes only over its own time constant and
  // that, on a machine whose HF orbit is a third of its current, pushed
  // points past the map's fold into a runaway. The held command of period
  // k (computed at k Ts, applied over [(k+1) Ts, (k+2) Ts)) has the
  // fundamental V sinc(w Ts / 2) e^{j(w (t - 1.5 Ts) + phase)}, whose flux
  // is that over j w (Rs neglected: Rs / (w_i L) < 1e-2).
  State x;
  m.Flux(id_ref, iq_ref, theta0, &x.psd, &x.psq);
  if (vi > 0) {
    const double r = vi * physics::ZohGain(wi, ts) / wi;
    const double a = align.injection_phase_rad - physics::ControlDelayAngle(wi, ts) - theta0;
    // (r / j) e^{j a} in the rotor frame at theta0.
    x.psd += r * std::sin(a);
    x.psq -= r * std::cos(a);
  }
  x.lpd = id_ref; x.lpq = iq_ref;
  x.i = vi > 0 ? m.Current(x.psd, x.psq, theta0, Vec2{id_ref, iq_ref}) : Vec2{id_ref, iq_ref};
  x.i_term = x.i;
  double int_d = cfg.motor.rs_ohm * id_ref, int_q = cfg.motor.rs_ohm * iq_ref;

  std::deque<std::pair<double, double>> cmd_hist;   // alpha-beta commands by period
  cmd_hist.push_back({0, 0});
  // Seed the history with the steady-state command so the first periods are
  // not a voltage step: the command of period -1, injection included (the
  // orbit the flux starts on assumes it).
  {
    double pd, pq;
    m.Flux(id_ref, iq_ref, theta0, &pd, &pq);
    const double ud = m.rs_ohm * id_ref - we * pq, uq = m.rs_ohm * iq_ref + we * pd;
    const double c = std::cos(theta0), s = std::sin(theta0);
    cmd_hist.clear();
    double ual, ube;
    InverseParkCs(ud, uq, c, s, &ual, &ube);
    ual += vi * std::cos(-wi * ts + align.injection_phase_rad);
    ube += vi * std::sin(-wi * ts + align.injection_phase_rad);
    for (int k = 0; k < 4; ++k) cmd_hist.push_back({ual, ube});
  }
  // The feedback average, seeded with one injection period at the
  // reference (the orbit's mean): a partly filled average reads the
  // orbit's first samples as a current error of up to the orbit's radius.
  std::deque<std::pair<double, double>> fb_hist(period, {id_ref, iq_ref});
  double fb_sum_d = static_cast<double>(period) * id_ref, fb_sum_q = static_cast<double>(period) * iq_ref;
  const size_t n_total = n_settle + n_rec;
  out.wave.t_s.reserve(n_rec);
  double acc_ud_app = 0, acc_uq_app = 0;
  size_t acc_app = 0;
  std::vector<std::pair<double, double>> cmds(n_total + 2);
  // The window's measured current, as its deviation from the reference
  // (small numbers: the variance from sums stays exact), and the periods at
  // a limit.
  double dev_d = 0, dev_q = 0, dev2 = 0;
  size_t limited = 0, saturated = 0;

  // The alpha-beta voltage held over sub-step `sub` (counted from the
  // run's start): the command of the period before (one PWM period late),
  // shifted further by the sampling_delay effect.
  auto held = [&](long sub) {
    sub -= delay_sub;
    const long per = (sub >= 0 ? sub / S : (sub - S + 1) / S) - 1;
    return per >= 0 ? cmds[per] : cmd_hist.front();
  };
  for (size_t k = 0; k < n_total; ++k) {
    const double t = static_cast<double>(k) * ts;
    const double th = theta0 + we * t;
    // --- Sample: sensors.
    const double c = std::cos(th), s = std::sin(th);
    // The sensors read the terminal current (iron-loss current included).
    // The loss current g e steps with the held voltage at each period
    // boundary; a sample there reads the mean of its values under the
    // period ending (x.i_term) and the one starting (its command is known:
    // it was computed one period ago), as the magnetising current, which is
    // continuous, is read at the boundary itself.
    Vec2 i_sample = x.i_term;
    if (m.g_fe_s != 0.0) {
      const std::pair<double, double> u = held(static_cast<long>(k) * S);
      double d[4];
      Vec2 im, next;
      Derivative(m, x, th, we, u.first, u.second, &d[0], &d[1], &d[2], &d[3], &im, &next);
      i_sample = Vec2{0.5 * (x.i_term.d + next.d), 0.5 * (x.i_term.q + next.q)};
    }
    double ial, ibe;
    InverseParkCs(i_sample.d, i_sample.q, c, s, &ial, &ibe);
    const Phases iph = InverseClarke(ial, ibe);
    double ia = iph.a, ib = iph.b, ic = iph.c;
    // Physics outside the catalogue acting on the sensors (interference,
    // crosstalk) before their gains, offsets, noise and quantisation.
    for (const auto& e : cfg.effects.unmodelled) e->Sense(t, &ia, &ib, &ic);
    const double lsb = cfg.sensors.adc_lsb_a;
    // The catalogue's sensor effects (gains, offsets; simulation/catalogue/).
    SenseCurrents(cfg.effects, &ia, &ib, &ic);
    auto sense = [&](double i) {
      double v = i + noise(*rng);
      if (lsb > 0) v = std::round(v / lsb) * lsb;
      return v;
    };
    const double ma = sense(ia), mb = sense(ib), mc = sense(ic);
    double th_meas = th + AngleSensorError(cfg.effects, th);
    for (const auto& e : cfg.effects.unmodelled) th_meas += e->AngleError(th, m.MechanicalAngle(th));
    // Encoder counts, read to the nearest count (an encoder whose zero is
    // aligned mid-count, as EOL benches calibrate it: no half-count bias).
    if (dtheta_enc > 0) th_meas = std::round(WrapAngle(th_meas) / dtheta_enc) * dtheta_enc;
    th_meas = WrapAngle(th_meas);
    if (align.theta_meas_rad && k >= n_settle && k - n_settle < align.theta_meas_rad->size()) {
      th_meas = WrapAngle((*align.theta_meas_rad)[k - n_settle]);
    }
    // --- Controller on injection-free feedback (moving average over one
    // injection period of the measured dq current).
    const AlphaBeta mab = Clarke(ma, mb, mc);
    const double mal = mab.alpha, mbe = mab.beta;
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
    double ff_d = -we * cfg.control.lq_nominal_h * ifq, ff_q = we * (cfg.control.ld_nominal_h * ifd + psi_pm_nom);
    if (cfg.control.gain_scheduled) {
      // The same map decouples: the back-EMF of its flux at the measured current.
      double pd, pq;
      m.Flux(ifd, ifq, th_meas, &pd, &pq);
      ff_d = -we * pq;
      ff_q = we * pd;
    }
    const double ud = kp_d * ed + int_d + ff_d;
    const double uq = kp_q * eq + int_q + ff_q;
    const double inj_c = std::cos(wi * t + align.injection_phase_rad),
                 inj_s = std::sin(wi * t + align.injection_phase_rad);
    // Inverse Park at the angle the rotor will have in the middle of the
    // period the command is applied in (theta + 1.5 w_e Ts): the usual ECU
    // delay compensation, so the dq command is the fundamental voltage the
    // machine sees (up to the hold's sinc gain), as steady_state.csv states.
    const double thc = th_meas + physics::ControlDelayAngle(we, ts);
    const double cc = std::cos(thc), sc = std::sin(thc);
    double ual, ube;
    InverseParkCs(ud, uq, cc, sc, &ual, &ube);
    ual += vi * inj_c;
    ube += vi * inj_s;
    // Modulator: linear range of space-vector PWM, |u| <= Udc / sqrt(3)
    // of the Udc the ECU measures.
    const double umag = std::hypot(ual, ube), u_lim = m.u_max_v / m.voltage_gain;
    if (umag > u_lim) {
      ual *= u_lim / umag;
      ube *= u_lim / umag;
      if (k >= n_settle) {
        out.clipped = true;
        ++limited;
        // The PI pair's own output beyond the limit (not only the injection).
        if (std::hypot(ud, uq) > u_lim) ++saturated;
      }
    }
    cmds[k] = {ual, ube};
    // What was sent to the modulator, back in the controller's dq frame
    // (differs from the PI output only when the voltage limit clipped).
    double ud_sent, uq_sent;
    ParkCs(ual - vi * inj_c, ube - vi * inj_s, cc, sc, &ud_sent, &uq_sent);
    if (k >= n_settle) {
      const size_t r = k - n_settle;
      out.wave.t_s.push_back(static_cast<double>(r) * ts);
      out.wave.ia_a.push_back(ma);
      out.wave.ib_a.push_back(mb);
      out.wave.ic_a.push_back(mc);
      out.wave.theta_e_rad.push_back(th_meas);
      out.wave.ualpha_ref_v.push_back(ual);
      out.wave.ubeta_ref_v.push_back(ube);
      out.wave.udc_v.push_back(m.udc_v / m.voltage_gain + unoise(*rng));
      out.mean_id_true += x.i.d;
      out.mean_iq_true += x.i.q;
      out.mean_id_meas += fd;
      out.mean_iq_meas += fq;
      dev_d += fd - id_ref;
      dev_q += fq - iq_ref;
      dev2 += (fd - id_ref) * (fd - id_ref) + (fq - iq_ref) * (fq - iq_ref);
      out.mean_ud_cmd += ud_sent;
      out.mean_uq_cmd += uq_sent;
      double pd, pq;
      m.Flux(x.i.d, x.i.q, th, &pd, &pq);
      out.mean_torque_nm += physics::ElectromagneticTorque(pp, pd, pq, x.i.d, x.i.q);
    }
    // --- Plant over [t_k, t_{k+1}): the command of period k-1 (one PWM
    // period late), shifted further by the sampling_delay effect.
    for (int j = 0; j < S; ++j) {
      std::pair<double, double> u = held(static_cast<long>(k) * S + j);
      // The fraction of a sub-step's delay: the sub-step's first part still
      // holds the command before.
      std::pair<double, double> u_early = delay_frac > 0.0 ? held(static_cast<long>(k) * S + j - 1) : u;
      const bool split = u_early != u;
      const double th_j = th + we * h * j;
      // A DC link whose ripple the modulator does not see scales every
      // voltage the inverter applies over the sub-step.
      double udc_factor = 1.0;
      for (const auto& e : cfg.effects.unmodelled) udc_factor *= e->UdcFactor(t + h * j);
      if (udc_factor != 1.0) {
        u.first *= udc_factor;
        u.second *= udc_factor;
        u_early.first *= udc_factor;
        u_early.second *= udc_factor;
      }
      if (k >= n_settle) {
        // Exact mean of the held alpha-beta voltage in the rotating frame
        // over the sub-step: e^{-j theta_mid} sin(y)/y, y = w_e h / 2.
        const double y = 0.5 * we * h;
        const double sinc = Sinc(y);
        const double cj = sinc * std::cos(th_j + y), sj = sinc * std::sin(th_j + y);
        double eal, ebe;
        double al, be;
        InverseParkCs(x.i.d, x.i.q, cj, sj, &al, &be);
        const Phases iab = InverseClarke(al, be);
        DeadTimeError(m, iab.a, iab.b, iab.c, &eal, &ebe);
        // Over a split sub-step the held voltage's mean over it.
        const double u1 = split ? delay_frac * u_early.first + (1.0 - delay_frac) * u.first : u.first;
        const double u2 = split ? delay_frac * u_early.second + (1.0 - delay_frac) * u.second : u.second;
        const double ua = m.voltage_gain * u1 + eal, ub = m.voltage_gain * u2 + ebe;
        double ud_app, uq_app;
        ParkCs(ua, ub, cj, sj, &ud_app, &uq_app);
        acc_ud_app += ud_app;
        acc_uq_app += uq_app;
        ++acc_app;
      }
      const State before = x;
      if (split) {
        Rk4(m, &x, th_j, we, delay_frac * h, u_early.first, u_early.second);
        Rk4(m, &x, th_j + we * delay_frac * h, we, (1.0 - delay_frac) * h, u.first, u.second);
      } else {
        Rk4(m, &x, th_j, we, h, u.first, u.second);
      }
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
  out.current_ripple_a = std::sqrt(std::max(0.0, dev2 / nr - (dev_d / nr) * (dev_d / nr) - (dev_q / nr) * (dev_q / nr)));
  out.voltage_limited_share = static_cast<double>(limited) / nr;
  out.controller_saturated_share = static_cast<double>(saturated) / nr;
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
  m.udc_v = cfg.drive.udc_v;
  m.ts_s = 1.0 / cfg.drive.f_pwm_hz;
  m.u_max_v = cfg.drive.udc_v / kSqrt3;
  ApplyEffectsToPlant(cfg.effects, &m);   // simulation/catalogue/
  m.pole_pairs = cfg.motor.pole_pairs;
  m.unmodelled = &cfg.effects.unmodelled;
  return m;
}

namespace {

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
  t.torque_nm = physics::ElectromagneticTorque(cfg.motor.pole_pairs, t.psi_d_wb, t.psi_q_wb, idt, iqt);
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

Plan WithSecondUdc(Plan plan, double udc_v, int every) {
  std::vector<PlanPoint> out;
  int locked = 0;
  for (const auto& p : plan.points) {
    out.push_back(p);
    if (p.speed_rpm != 0.0) continue;
    if (locked++ % std::max(1, every) != 0) continue;
    PlanPoint q = p;
    q.id = p.id + "u";
    q.udc_v = udc_v;
    out.push_back(q);
  }
  plan.points = std::move(out);
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
  // The magnet grade's coefficient, as a bench knows it from the datasheet
  // (docs/recording-format.md, "Magnet temperature").
  mf.motor.psi_pm_temp_coeff_per_k = cfg.motor.psi_pm_temp_coeff_per_k;
  mf.drive.udc_v = cfg.drive.udc_v;
  mf.drive.f_pwm_hz = cfg.drive.f_pwm_hz;
  mf.drive.f_sample_hz = cfg.drive.f_pwm_hz;
  mf.drive.dead_time_s = cfg.drive.nominal_dead_time_s;
  mf.drive.dead_time_compensated = true;
  mf.injection = io::InjectionInfo{"rotating", cfg.injection.amplitude_v, cfg.injection.frequency_hz};
  std::mt19937_64 rng(cfg.seed);
  // The magnets' temperature over the test (magnet_temperature drifting):
  // a linear rise over every recorded item, points then steady-state rows.
  const size_t items = plan.points.size() + plan.steady_state.size();
  auto magnet_rise = [&](size_t item) {
    return items > 1 ? cfg.effects.magnet_temp_rise_k * static_cast<double>(item) / static_cast<double>(items - 1)
                     : 0.0;
  };
  for (size_t k = 0; k < plan.points.size(); ++k) {
    const auto& pt = plan.points[k];
    PlantModel m = MakePlant(cfg, pt.temperature_c + magnet_rise(k));
    m.sector = pt.sector;
    if (pt.udc_v > 0) {
      m.udc_v = pt.udc_v;
      m.u_max_v = pt.udc_v / kSqrt3;
    }
    // stator_temperature_drift: the winding warms linearly over the locked
    // and rotating points in plan order, then stays warm (steady state).
    m.rs_ohm *= 1.0 + kCopperAlphaPerK * cfg.effects.winding_temp_rise_k *
                          (plan.points.size() > 1 ? static_cast<double>(k) / (plan.points.size() - 1) : 0.0);
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
    for (size_t r = 0; r < plan.steady_state.size(); ++r) {
      const auto& ss = plan.steady_state[r];
      PlantModel m = MakePlant(cfg, ss.temperature_c + magnet_rise(plan.points.size() + r));
      m.rs_ohm *= 1.0 + kCopperAlphaPerK * cfg.effects.winding_temp_rise_k;
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
      // The transducer reads the air-gap torque less the mechanical loss
      // between them (torque_loss).
      row.torque_nm = run.mean_torque_nm -
                      TorqueReadingLoss(cfg.effects, ss.speed_rpm) +
                      tnoise(rng);
      row.temperature_c = ss.temperature_c;
      // What the bench held over the window (PointRun says how each is taken).
      row.current_ripple_a = run.current_ripple_a;
      row.voltage_limited_share = run.voltage_limited_share;
      row.controller_saturated_share = run.controller_saturated_share;
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
