#include "diagnosis/internal.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <map>
#include <tuple>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "identification/demod.h"
#include "identification/inductance.h"
#include "physics/inverter.h"
#include "physics/speed.h"

namespace fluxcal::diag::detail {

// The dead-time voltage error per second of dead time, in the command's
// units: (Udc/Ts) Clarke(tanh(i_x / i_th)) -- the command must add this to
// hold the current when Td is not compensated.
Complex DeadTimeUnit(double ia, double ib, double ic, double udc, double ts, double ith_a) {
  const sim::AlphaBeta e = physics::SoftSignVector(ia, ib, ic, udc / ts, ith_a);
  return Complex(e.alpha, e.beta);
}

namespace {

Complex DeadTimeInterval(const io::Waveform& w, size_t s, double udc, double ts, double ith_a) {
  const size_t e = s + 1 < w.size() ? s + 1 : s;
  const double k = udc / ts;
  const double ea = k * MeanSoftSign(w.ia_a[s], w.ia_a[e], ith_a), eb = k * MeanSoftSign(w.ib_a[s], w.ib_a[e], ith_a),
               ec = k * MeanSoftSign(w.ic_a[s], w.ic_a[e], ith_a);
  return sim::ClarkeComplex(ea, eb, ec);
}

}  // namespace

void SetSoftSignCurrent(const io::RecordingSet& set, double ith_a, Model* m) {
  m->ith_a = ith_a;
  const auto& mf = set.manifest;
  const double fs = mf.drive.f_sample_hz;
  const double f_pwm = 1.0 / m->ts;
  const double udc_nom = mf.drive.udc_v.value_or(0.0);
  // Locked and rotating points: the recorded phase currents' soft signs,
  // projected as the demodulators and the held-voltage means project them.
  auto signatures = [&](size_t wave, size_t n, Complex* hf, Complex* neg, Complex* dc, Complex* hf_v,
                        Complex* neg_v, Complex* dc_v) {
    const auto& w = set.waveforms[wave];
    *hf = *neg = *dc = *hf_v = *neg_v = *dc_v = 0;
    for (size_t s = 0; s < n; ++s) {
      const double udc = std::isnan(w.udc_v[s]) ? udc_nom : w.udc_v[s];
      // Per volt of switch threshold; the dead time's is Udc / Ts times it.
      const Complex e_v = DeadTimeInterval(w, s, m->ts, m->ts, ith_a);
      const Complex e = e_v * (udc / m->ts);
      const double t = static_cast<double>(s) / fs;
      *hf += e * std::polar(1.0, -m->w_i * t);
      *hf_v += e_v * std::polar(1.0, -m->w_i * t);
      *neg_v += e_v * std::polar(1.0, m->w_i * t - 2 * w.theta_e_rad[s]);
      *dc_v += e_v * std::polar(1.0, -w.theta_e_rad[s]);
      *neg += e * std::polar(1.0, m->w_i * t - 2 * w.theta_e_rad[s]);
      *dc += e * std::polar(1.0, -w.theta_e_rad[s]);
    }
    const double inv = 1.0 / static_cast<double>(std::max<size_t>(n, 1));
    *hf *= inv; *neg *= inv; *dc *= inv; *hf_v *= inv; *neg_v *= inv; *dc_v *= inv;
  };
  // A locked point's DC observation averages the same samples of the same
  // waveform as its HF observation (BuildModel): one pass serves both.
  std::map<size_t, std::pair<Complex, Complex>> dc_of_wave;   // dead, dead_v
  for (auto& o : m->hf) {
    Complex hf, neg, dc, hf_v, neg_v, dc_v;
    signatures(o.wave, o.samples, &hf, &neg, &dc, &hf_v, &neg_v, &dc_v);
    dc_of_wave[o.wave] = {dc, dc_v};
    // The error of interval [t_k, t_k+1) acts in that interval, one period
    // earlier than a command issued at t_k: EffectiveVoltage's 1.5-period
    // delay less one period.
    const double w2 = 2 * o.w_e - m->w_i;
    o.dead_hf = ident::EffectiveVoltage(hf, m->w_i, f_pwm) * std::polar(1.0, m->w_i * m->ts);
    o.dead_neg = ident::EffectiveVoltage(neg, w2, f_pwm) * std::polar(1.0, w2 * m->ts);
    o.dead_hf_v = ident::EffectiveVoltage(hf_v, m->w_i, f_pwm) * std::polar(1.0, m->w_i * m->ts);
    o.dead_neg_v = ident::EffectiveVoltage(neg_v, w2, f_pwm) * std::polar(1.0, w2 * m->ts);
  }
  for (auto& d : m->dc) {
    const auto it = dc_of_wave.find(d.wave);
    if (it != dc_of_wave.end()) {
      std::tie(d.dead, d.dead_v) = it->second;
      continue;
    }
    Complex hf, neg, dc, hf_v, neg_v, dc_v;
    signatures(d.wave, d.samples, &hf, &neg, &dc, &hf_v, &neg_v, &dc_v);
    d.dead = dc;
    d.dead_v = dc_v;
  }
  for (auto& o : m->ss) {
    // Fundamental of the dead-time error over one electrical revolution.
    Complex dead_v = 0;
    const double mag = std::hypot(o.id_a, o.iq_a), gam = std::atan2(o.iq_a, o.id_a);
    for (int s = 0; s < 360; ++s) {
      const double th = 2 * kPi * s / 360;
      const double ia = mag * std::cos(th + gam), ib = mag * std::cos(th + gam - 2 * kPi / 3),
                   ic = mag * std::cos(th + gam + 2 * kPi / 3);
      dead_v += DeadTimeUnit(ia, ib, ic, m->ts, m->ts, ith_a) * std::polar(1.0, -th);
    }
    o.dead = dead_v * (udc_nom / m->ts) / 360.0;
    o.dead_v = dead_v / 360.0;
  }
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
  m.udc_nom_v = udc_nom;
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
    o.w_e = o.speed_rpm == 0 ? 0.0 : physics::RpmToElectricalRadS(id.speed_rpm, m.pole_pairs);
    o.locked = o.speed_rpm == 0;
    o.theta = w.theta_e_rad[0];
    // The manifest lists points in recording order.
    o.progress = ids->size() > 1 ? static_cast<double>(k) / static_cast<double>(ids->size() - 1) : 0.0;
    o.i0 = id.i0_a; o.i1 = id.i1_a; o.v_eff = id.v_eff_v; o.v_neg_eff = id.v_neg_eff_v;
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
    const bool near_zero = id.near_zero_fraction > ident::kNearZeroFraction;
    const double floor = (near_zero ? 0.02 : 0.0025) * std::abs(o.i0);
    o.sigma0 = std::sqrt(lsq->var_i0_a2 + floor * floor);
    o.sigma1 = std::sqrt(lsq->var_i1_a2 + floor * floor);
    o.scale = std::abs(o.i0);
    // Window means for the spatial-harmonic and position terms, and the
    // held command per injection period (the DC observation's noise).
    const size_t n = lsq->samples_used;
    o.wave = k;
    o.samples = n;
    double udc_sum = 0;
    std::vector<Complex> per_period;
    const size_t period = static_cast<size_t>(std::llround(fs / mf.injection->frequency_hz));
    Complex acc_u = 0;
    for (size_t s = 0; s < n; ++s) {
      udc_sum += std::isnan(w.udc_v[s]) ? udc_nom : w.udc_v[s];
      const double t = static_cast<double>(s) / fs;
      o.mean_e2 += std::polar(1.0, -2 * w.theta_e_rad[s]);
      if (!o.locked) {
        for (int h = 0; h < 4; ++h) {
          const int nh = kHarmOrders[h];
          o.harm_p[h] += std::polar(1.0, (nh + 1) * w.theta_e_rad[s] - m.w_i * t);
          o.harm_q[h] += std::polar(1.0, -(nh - 1) * w.theta_e_rad[s] - m.w_i * t);
        }
      }
      acc_u += Complex(w.ualpha_ref_v[s], w.ubeta_ref_v[s]) * std::polar(1.0, -w.theta_e_rad[s]);
      if ((s + 1) % period == 0) { per_period.push_back(acc_u / static_cast<double>(period)); acc_u = 0; }
    }
    o.mean_e2 /= static_cast<double>(n);
    for (int h = 0; h < 4; ++h) {
      o.harm_p[h] /= static_cast<double>(n);
      o.harm_q[h] /= static_cast<double>(n);
    }
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
      d.wave = k;
      d.samples = n;
      d.udc_v = udc_sum / static_cast<double>(n);
      // Batch-means noise plus 5 mV: the command's resolution after the
      // bench's own (nominal) dead-time compensation and quantisation.
      d.sigma = std::sqrt(var + 0.005 * 0.005);
      m.dc.push_back(d);
    }
  }
  for (size_t r = 0; r < set.steady_state.size(); ++r) {
    const auto& row = set.steady_state[r];
    SsObs o;
    o.progress = set.steady_state.size() > 1 ? static_cast<double>(r) / static_cast<double>(set.steady_state.size() - 1)
                                             : 0.5;
    o.id_a = row.id_a; o.iq_a = row.iq_a; o.speed_rpm = row.speed_rpm;
    o.w_e = physics::RpmToElectricalRadS(row.speed_rpm, m.pole_pairs);
    o.u = sim::ZohGain(o.w_e, m.ts) * Complex(row.ud_ref_v, row.uq_ref_v);
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
  double w_sum = 0;
  for (const auto& o : m.ss) {
    if (!o.has_torque) continue;
    t2 += o.torque * o.torque;
    w_sum += std::abs(physics::RpmToMechanicalRadS(o.speed_rpm));
    ++nt;
  }
  if (nt) m.torque_ref_rad_s = w_sum / nt;
  // The scales of the materiality floors (Model::FloorScaleValue).
  for (const auto& p : mf.points) m.scale_current_a = std::max(m.scale_current_a, std::hypot(p.id_ref_a, p.iq_ref_a));
  for (const auto& o : m.ss) {
    m.scale_current_a = std::max(m.scale_current_a, std::hypot(o.id_a, o.iq_a));
    if (o.has_torque) m.scale_torque_nm = std::max(m.scale_torque_nm, std::abs(o.torque));
  }
  double l_sum = 0;
  int nl = 0;
  for (const auto& id : *ids) {
    if (!std::isfinite(id.ld_h) || !std::isfinite(id.lq_h)) continue;
    l_sum += 0.5 * (id.ld_h + id.lq_h);
    ++nl;
  }
  if (nl) m.scale_inductance_h = l_sum / nl;
  m.scale_rs_ohm = m.rs_nom;
  if (!(m.scale_rs_ohm > 0)) {
    std::vector<double> r;
    for (const auto& d : m.dc) {
      const double i = std::hypot(d.id_a, d.iq_a);
      if (i > 0.05 * m.scale_current_a) r.push_back(std::abs(d.u) / i);
    }
    if (!r.empty()) {
      std::nth_element(r.begin(), r.begin() + r.size() / 2, r.end());
      m.scale_rs_ohm = r[r.size() / 2];
    }
  }
  m.scale_udc_v = udc_nom;
  if (!(m.scale_udc_v > 0)) {
    double u_sum = 0;
    int nu = 0;
    for (const auto& d : m.dc) {
      if (d.udc_v > 0) { u_sum += d.udc_v; ++nu; }
    }
    if (nu) m.scale_udc_v = u_sum / nu;
  }
  if (!m.dc.empty()) m.dc_scale_v = std::max(0.01, std::sqrt(dc2 / m.dc.size()));
  double udc_lo = 0, udc_hi = 0;
  for (const auto& d : m.dc) {
    if (!(d.udc_v > 0)) continue;
    udc_lo = udc_lo > 0 ? std::min(udc_lo, d.udc_v) : d.udc_v;
    udc_hi = std::max(udc_hi, d.udc_v);
  }
  if (udc_lo > 0) m.udc_ratio = udc_hi / udc_lo;
  if (m.udc_ratio > kTwoUdcRatio) {
    // The set's main DC-link voltage is its median point's; points more than
    // 5 % away were recorded at the second one.
    std::vector<double> u;
    for (const auto& d : m.dc) if (d.udc_v > 0) u.push_back(d.udc_v);
    std::nth_element(u.begin(), u.begin() + u.size() / 2, u.end());
    const double main_udc = u[u.size() / 2];
    for (auto& d : m.dc) d.second_udc = d.udc_v > 0 && std::abs(d.udc_v - main_udc) > 0.05 * main_udc;
  }
  if (nt) m.torque_scale_nm = std::max(0.1, std::sqrt(t2 / nt));
  SetSoftSignCurrent(set, kIth, &m);
  if (auto st = InitSurfaces(set, *ids, &m); !st.ok()) return st;
  return m;
}

void SetSurfaces(const fit::Calibration& cal, Model* m) {
  m->surf = cal.family();
  m->surf_init = cal.params();
  m->surf_init[0] = 0.0;   // psi_pm is Model::PsiPm's (nominal x the kPsi block)
  m->surf_k_eff = cal.summary.effective_parameters > 0 ? cal.summary.effective_parameters
                                                       : static_cast<double>(m->surf.NumParams() - 1);
  const int k = m->surf.NumParams();
  m->surf_R.resize(0, k);
  m->surf_lambda = cal.summary.smoothing_lambda;
  m->surf_anisotropy_q = cal.summary.smoothing_anisotropy_q;
  m->surf_curvature_weight = cal.summary.smoothing_curvature_weight;
  const Eigen::MatrixXd P =
      fit::SmoothingPenalty(m->surf, cal.summary.smoothing_anisotropy_q, cal.summary.smoothing_curvature_weight);
  if (m->surf_lambda > 0 && P.rows() > 0) {
    // lambda |P c|^2 = lambda |R c|^2 with R the Cholesky factor of
    // P^T P + eps I (eps as fit.cc's: the directions nothing sees stay put).
    Eigen::MatrixXd B = P.transpose() * P;
    B.diagonal().array() += 1e-9 * B.trace() / k;
    Eigen::LLT<Eigen::MatrixXd> llt(B);
    if (llt.info() == Eigen::Success) m->surf_R = Eigen::MatrixXd(llt.matrixU());
  }
}

absl::Status InitSurfaces(const io::RecordingSet& set, const std::vector<ident::HfPointResult>& ids, Model* m) {
  const fit::FitData data = fit::FitDataFromRecording(set, ids);
  // Small-signal (fit::FitOptions::large_signal_hf): the joint model
  // predicts each HF point from the surfaces' Jacobian at its mean current
  // (observations.cc), so its surfaces are the fit of that same model.
  // Its penalty on the inductance's slopes alone (curvature weight 0, as
  // before fit::kSmoothingCurvatureWeight): the residual checks read the
  // injection's harmonics in the phase currents, which the inductance's
  // curvature along the HF orbit makes, and a penalty on that curvature
  // biases it: with it the clean deep-saturation twin set was left
  // `unexplained`, harmonic -6 of the injection remaining
  // (OtherMachines.CleanNamesNothingDeadTimeAloneAndCloser).
  fit::FitOptions fo;
  fo.large_signal_hf = false;
  fo.smoothing_curvature_weight = 0.0;
  auto cal = fit::Fit(data, fo);
  if (!cal.ok()) {
    return absl::Status(cal.status().code(),
                        absl::StrCat("diagnosis: the set's own calibration (the baseline's magnetics) could not be "
                                     "fitted: ", cal.status().message()));
  }
  SetSurfaces(*cal, m);
  return absl::OkStatus();
}

}  // namespace fluxcal::diag::detail
