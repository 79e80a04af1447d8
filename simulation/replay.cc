// Open- and closed-loop replay of a recording on the twin (docs/simulation.md).
#include <algorithm>
#include <cmath>
#include <complex>
#include <random>

#include <Eigen/Dense>

#include "absl/strings/str_cat.h"
#include "simulation/bench.h"
#include "simulation/catalogue/catalogue_effect.h"
#include "simulation/twin.h"

namespace fluxcal::sim {
namespace {


// The plant both replays drive: `model` as the magnetics, the effects the
// caller wants included, the recording's drive.
PlantModel ReplayPlant(const MagneticModel& model, double temperature_c, double rs_ohm, const Effects& e,
                       double udc_v, double ts_s, double u_max_v) {
  PlantModel m;
  ToArray(SaturationParams{}, m.p);
  m.map = &model;
  m.map_temperature_c = temperature_c;
  m.rs_ohm = rs_ohm;
  m.udc_v = udc_v;
  m.ts_s = ts_s;
  m.u_max_v = u_max_v;
  ApplyEffectsToPlant(e, &m);   // simulation/catalogue/
  return m;
}

// The true DC-link voltage of one recorded point: the mean of its udc_v
// column (a plan may repeat points at a second Udc) undone by the sense gain
// the replay assumes; the manifest's drive.udc_v where the column is empty.
double PointUdc(const io::Waveform& w, double manifest_udc_v, const Effects& e) {
  double sum = 0;
  size_t n = 0;
  for (double u : w.udc_v) {
    if (std::isfinite(u)) { sum += u; ++n; }
  }
  return n > 0 ? sum / static_cast<double>(n) / e.udc_sense_gain : manifest_udc_v;
}

// The least-squares line through a point's unwrapped recorded angle:
// theta(k) = intercept + slope k (rad, rad per sample).
struct AngleLine {
  double intercept_rad = 0, slope_rad = 0;
};
AngleLine FitAngleLine(const io::Waveform& w) {
  const size_t n = w.size();
  double sx = 0, sy = 0, sxx = 0, sxy = 0, unwrapped = n > 0 ? w.theta_e_rad[0] : 0.0;
  for (size_t k = 0; k < n; ++k) {
    if (k > 0) unwrapped += std::remainder(w.theta_e_rad[k] - w.theta_e_rad[k - 1], 2 * kPi);
    const double x = static_cast<double>(k);
    sx += x; sy += unwrapped; sxx += x * x; sxy += x * unwrapped;
  }
  const double nn = static_cast<double>(n);
  AngleLine a;
  const double den = nn * sxx - sx * sx;
  a.slope_rad = den > 0 ? (nn * sxy - sx * sy) / den : 0.0;
  a.intercept_rad = n > 0 ? (sy - a.slope_rad * sx) / nn : 0.0;
  return a;
}

}  // namespace

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
                                     PointUdc(w, mf.drive.udc_v.value_or(50.0), opt.effects), ts, 1e9);
    // Inverting measured = true + error(true) to first order in the error
    // (a fraction of a degree): error(measured - offset). A rotating point
    // turns at constant speed (the test holds it), so its true angle is the
    // least-squares line through the recorded one: an encoder's count
    // quantisation (one count per sample, now and then two) read as the
    // rotor's own motion put a speed spike into the back-EMF at every extra
    // count and a current jump into the replay (every 25 ms at 150 rpm on a
    // 4096-count encoder); at speed the angle harmonic averages out, as in
    // ReplayClosedLoop.
    const bool rotating = std::abs(mf.points[p].speed_rpm) > 0.0;
    const AngleLine line = FitAngleLine(w);
    auto true_theta = [&](size_t k) {
      if (rotating) return line.intercept_rad + line.slope_rad * static_cast<double>(k) - opt.effects.offset_rad;
      return w.theta_e_rad[k] - AngleSensorError(opt.effects, w.theta_e_rad[k] - opt.effects.offset_rad);
    };
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
    const auto& fx = opt.effects;
    const double ia = (w.ia_a[1] - fx.offset_a_a) / fx.gain_a, ib = (w.ib_a[1] - fx.offset_b_a) / fx.gain_b,
                 ic = (w.ic_a[1] - fx.offset_c_a) / fx.gain_c;
    const AlphaBeta ab = Clarke(ia, ib, ic);
    const double al = ab.alpha, be = ab.beta;
    const double c0 = std::cos(th[1]), s0 = std::sin(th[1]);
    State x;
    x.i = Vec2{c0 * al + s0 * be, -s0 * al + c0 * be};
    m.Flux(x.i.d, x.i.q, th[1], &x.psd, &x.psq);
    x.lpd = x.i.d;
    x.lpq = x.i.q;
    x.i_term = x.i;
    ReplayPoint rp;
    rp.point = mf.points[p].id;
    rp.ia_a.push_back(w.ia_a[0]);   // sample 0 is not simulated
    rp.ib_a.push_back(w.ib_a[0]);
    rp.ic_a.push_back(w.ic_a[0]);
    rp.angle_error_rad.resize(n);
    for (size_t k = 0; k < n; ++k) {
      rp.angle_error_rad[k] = AngleSensorError(opt.effects, true_theta(k)) - opt.effects.offset_rad;
    }
    double se = 0;
    for (size_t k = 1; k < n; ++k) {
      const double c = std::cos(th[k]), s = std::sin(th[k]);
      double a, b;
      InverseParkCs(x.i_term.d, x.i_term.q, c, s, &a, &b);
      const Phases ph = InverseClarke(a, b);
      const double sa = fx.gain_a * ph.a + fx.offset_a_a;
      const double sb = fx.gain_b * ph.b + fx.offset_b_a;
      const double sc = fx.gain_c * ph.c + fx.offset_c_a;
      rp.ia_a.push_back(sa);
      rp.ib_a.push_back(sb);
      rp.ic_a.push_back(sc);
      se += (sa - w.ia_a[k]) * (sa - w.ia_a[k]) + (sb - w.ib_a[k]) * (sb - w.ib_a[k]) +
            (sc - w.ic_a[k]) * (sc - w.ic_a[k]);
      if (k + 1 == n) break;
      const double we = (th[k + 1] - th[k]) / ts;
      // Interval [t_k, t_k+1) holds the command of row k-1 (row 0 for the
      // first interval, whose predecessor was not recorded), shifted by the
      // sampling_delay effect: delay = (d + a) Ts, so the interval holds row
      // k-1-d-1 for its first a Ts and row k-1-d for the rest, each part
      // integrated in sub-steps of at most h (a delay rounded to whole
      // sub-steps, 20 us here, was another delay than the one fitted).
      const double q = std::max(0.0, opt.effects.delay_s) / ts;
      const long d = static_cast<long>(std::floor(q));
      const double frac = q - static_cast<double>(d);
      auto row_of = [&](long r) { return std::clamp<long>(r, 0, static_cast<long>(n) - 1); };
      double t0 = 0.0;
      for (int part = 0; part < 2; ++part) {
        const double len = (part == 0 ? frac : 1.0 - frac) * ts;
        if (len <= 1e-12 * ts) continue;
        const long row = row_of(static_cast<long>(k) - 1 - d - (part == 0 ? 1 : 0));
        const int steps = std::max(1, static_cast<int>(std::ceil(len / h - 1e-9)));
        const double hs = len / steps;
        for (int j = 0; j < steps; ++j) {
          Rk4(m, &x, th[k] + we * (t0 + hs * j), we, hs, w.ualpha_ref_v[row], w.ubeta_ref_v[row]);
        }
        t0 += len;
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
    const double udc_v = PointUdc(w, cfg.drive.udc_v, opt.effects);
    const PlantModel m = ReplayPlant(model, pt.temperature_c.value_or(25.0), opt.rs_ohm, opt.effects, udc_v, ts,
                                     udc_v / kSqrt3);
    // Align the run's record window with the recording: the plant's angle
    // follows the recorded one less the offset effect, and the
    // injection has the recorded phase at its first sample.
    // The plant's angle: the least-squares line through the unwrapped
    // recorded angle (an encoder's quantisation averages out along it).
    const AngleLine line = FitAngleLine(w);
    const double slope = line.slope_rad, intercept = line.intercept_rad;
    const double we = slope * fs;
    const double speed_rpm = ElectricalRadSToRpm(we, cfg.motor.pole_pairs);
    const size_t n_settle = static_cast<size_t>(std::llround(opt.settle_s * fs));
    const double settle_s = static_cast<double>(n_settle) * ts;
    // At standstill the reading's error is the one at the locked angle; at
    // speed the line through the readings averages its harmonic out.
    const double error_rad = std::abs(speed_rpm) < 1.0
                                 ? AngleSensorError(opt.effects, intercept - opt.effects.offset_rad)
                                 : opt.effects.offset_rad;
    const double theta0 = intercept - error_rad - we * settle_s;
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

}  // namespace fluxcal::sim
