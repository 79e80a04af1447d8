#include "identification/demod.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <vector>

#include <Eigen/Dense>

#include "absl/strings/str_cat.h"
#include "identification/demod_kernels.h"
#include "physics/delay.h"

namespace fluxcal::ident {
namespace {

constexpr double kTwoPi = 2.0 * std::numbers::pi;

absl::Status CheckRates(const PhaseSamples& s) {
  if (!(s.f_sample_hz > 0) || !(s.f_injection_hz > 0) || s.f_injection_hz >= s.f_sample_hz / 2) {
    return absl::InvalidArgumentError(absl::StrCat(
        "field 'f_injection_hz': need 0 < f_injection_hz < f_sample_hz / 2, got f_injection_hz=",
        s.f_injection_hz, " f_sample_hz=", s.f_sample_hz));
  }
  if (s.ia_a == nullptr || s.ib_a == nullptr || s.ic_a == nullptr || s.theta_e_rad == nullptr) {
    return absl::InvalidArgumentError("field 'ia_a': missing sample arrays");
  }
  return absl::OkStatus();
}

// The residual's spectral density near the frequencies of I0 and I1, as
// E|noise|^2 per sample (s0, s1; white noise: both equal the residual's
// mean power), its dead-time sidebands and its power at other harmonics of
// the injection (e's dead_time_sideband_ratio and harmonic_ratio, demod.h).
// The variance of a regressor's amplitude is its diagonal of G^-1 times
// the density at its own frequency (a stationary noise's periodogram; Kay,
// Fundamentals of Statistical Signal Processing: Estimation Theory, 1993,
// Sec. 15.7); the residual's mean power stands for it only when the noise
// is white. It is not: at standstill the orbit's harmonics (saturation,
// the describing function of docs/fitting.md), at speed the fundamental's,
// lie at +-3 w_i, +-5 w_i, multiples of w_e -- deterministic, orthogonal
// to the regressors over whole periods, and up to 50 times the power of
// the noise around w_i on the twin's knee machines. The density is the
// periodogram's mean over the Fourier bins (spacing 2 pi / (n Ts)) beside
// each frequency, +-1..kernels::kResidualBins bins (10: the density to
// +-16 %, 40 real degrees of freedom), of the residual shifted to baseband: exact bins, so a component of whole cycles in the window adds
// nothing (block means, tried, leak it through their sinc sidelobes). The
// sums are one vectorised pass (demod_kernels.h, ResidualSumsOf).
void ResidualAnalysis(const PhaseSamples& s, size_t n, double w_rad_s, double w_e_rad_s, PhasorEstimate* e,
                      double* s0, double* s1) {
  const double ts = 1.0 / s.f_sample_hz;
  const double t_mid = 0.5 * static_cast<double>(n - 1) * ts;
  // Sidebands resolved: 6 w_e at least two Fourier bins from the phasor.
  const double window_s = static_cast<double>(n) * ts;
  const bool sidebands = 6.0 * std::abs(w_e_rad_s) * window_s >= 2.0 * kTwoPi;
  const double model[8] = {e->i0_a.real(), e->i0_a.imag(), e->i1_a.real(), e->i1_a.imag(),
                           e->fundamental_dq_a.real(), e->fundamental_dq_a.imag(),
                           e->fundamental_drift_a_per_s.real(), e->fundamental_drift_a_per_s.imag()};
  const kernels::PhaseArrays arrays{s.ia_a, s.ib_a, s.ic_a, s.theta_e_rad, s.n};
  const kernels::ResidualSums sums =
      kernels::ResidualSumsOf(arrays, n, w_rad_s * ts, t_mid, ts, model, sidebands, kernels::BestIsa());
  auto c = [](const double* v) { return Complex(v[0], v[1]); };
  double p0 = 0, p1 = 0;
  for (int b = 0; b < 2 * kernels::kResidualBins; ++b) {
    p0 += std::norm(c(sums.bins0[b]));
    p1 += std::norm(c(sums.bins1[b]));
  }
  const double scale = 1.0 / (2.0 * kernels::kResidualBins * static_cast<double>(n));
  *s0 = p0 * scale;
  *s1 = p1 * scale;
  double hp = 0;
  for (const auto& h : sums.harm) hp += std::norm(c(h) / static_cast<double>(n));
  const double i0_power = std::norm(e->i0_a);
  e->harmonic_ratio = i0_power > 0 ? hp / i0_power : 0.0;
  e->dead_time_sideband_ratio = std::numeric_limits<double>::quiet_NaN();
  const double i0 = std::abs(e->i0_a);
  if (sidebands && i0 > 0) {
    double worst = 0;
    for (int j = 0; j < 4; ++j) worst = std::max({worst, std::abs(c(sums.side0[j])), std::abs(c(sums.side1[j]))});
    e->dead_time_sideband_ratio = worst / static_cast<double>(n) / i0;
  }
}

}  // namespace

size_t WholePeriodSamples(size_t n, double f_sample_hz, double f_injection_hz, double* periods) {
  const double samples_per_period = f_sample_hz / f_injection_hz;
  const double whole = std::floor(static_cast<double>(n) / samples_per_period + 1e-9);
  size_t used = static_cast<size_t>(std::llround(whole * samples_per_period));
  if (used > n) used = n;
  if (periods) *periods = whole;
  return used;
}

double EstimateSpeedRadPerS(const double* theta, size_t n, double f_sample_hz) {
  if (n < 2) return 0.0;
  return kernels::AngleSlopeRadPerSample(theta, n, kernels::BestIsa()) * f_sample_hz;
}

absl::StatusOr<PhasorEstimate> LsqDemodulate(const PhaseSamples& s) {
  if (auto st = CheckRates(s); !st.ok()) return st;
  PhasorEstimate out;
  const size_t n = WholePeriodSamples(s.n, s.f_sample_hz, s.f_injection_hz, &out.periods_used);
  if (out.periods_used < 2) {
    return absl::InvalidArgumentError(absl::StrCat(
        "field 't_s': ", s.n, " samples hold fewer than 2 injection periods"));
  }
  out.samples_used = n;
  const double ts = 1.0 / s.f_sample_hz;
  const double w = kTwoPi * s.f_injection_hz;
  const double t_mid = 0.5 * static_cast<double>(n - 1) * ts;
  const double nn = static_cast<double>(n);

  // Normal equations G x = h for the four complex regressors
  //   b0 = e^{jwt}, b1 = e^{j2theta} e^{-jwt}, b2 = e^{jtheta}, b3 = tau e^{jtheta},
  // G_ij = sum conj(b_i) b_j, h_i = sum conj(b_i) y (sums in demod_kernels.h).
  // |b0| = |b1| = |b2| = 1, so G00 = G11 = G22 = n; conj(b1) b2 = conj(conj(b0) b2),
  // so G12 = conj(G02) and G13 = conj(G03); tau_k = (k - (n-1)/2) Ts is
  // symmetric, so G23 = sum tau = 0 and G33 = sum tau^2 = Ts^2 n (n^2 - 1) / 12.
  const kernels::PhaseArrays arrays{s.ia_a, s.ib_a, s.ic_a, s.theta_e_rad, s.n};
  const kernels::LsqSums k = kernels::LsqNormalSums(arrays, n, w * ts, t_mid, ts,
                                                    kernels::BestIsa());
  auto c = [](const double* v) { return Complex(v[0], v[1]); };
  Eigen::Matrix4cd G;
  G(0, 0) = nn; G(1, 1) = nn; G(2, 2) = nn; G(3, 3) = ts * ts * nn * (nn * nn - 1.0) / 12.0;
  G(0, 1) = c(k.g01); G(0, 2) = c(k.g02); G(0, 3) = c(k.g03);
  G(1, 2) = std::conj(c(k.g02)); G(1, 3) = std::conj(c(k.g03)); G(2, 3) = 0.0;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < i; ++j) G(i, j) = std::conj(G(j, i));
  const Eigen::Vector4cd h(c(k.h0), c(k.h1), c(k.h2), c(k.h3));
  Eigen::LDLT<Eigen::Matrix4cd> ldlt(G);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
    return absl::InvalidArgumentError("field 'theta_e_rad': regressors are degenerate "
                                      "(2 w_e too close to w_i?)");
  }
  const Eigen::Vector4cd x = ldlt.solve(h);
  const Eigen::Matrix4cd Ginv = ldlt.solve(Eigen::Matrix4cd::Identity());
  // Residual sum of squares from the normal equations: RSS = y^H y - x^H h.
  const double rss = std::max(0.0, k.yy - (x.adjoint() * h)(0).real());
  out.i0_a = x(0);
  out.i1_a = x(1);
  out.fundamental_dq_a = x(2);
  out.fundamental_drift_a_per_s = x(3);
  out.w_e_rad_s = EstimateSpeedRadPerS(s.theta_e_rad, n, s.f_sample_hz);
  // Noise density at each phasor's own frequency, and the sidebands.
  double s0 = 0, s1 = 0;
  ResidualAnalysis(s, n, w, out.w_e_rad_s, &out, &s0, &s1);
  out.var_i0_a2 = s0 * Ginv(0, 0).real();
  out.var_i1_a2 = s1 * Ginv(1, 1).real();
  out.cov_i0_i1_a2 = std::sqrt(s0 * s1) * Ginv(0, 1);
  out.residual_rms_a = std::sqrt(rss / nn);
  return out;
}

absl::StatusOr<PhasorEstimate> PaperDemodulate(const PhaseSamples& s, bool compensate) {
  if (auto st = CheckRates(s); !st.ok()) return st;
  PhasorEstimate out;
  const double ts = 1.0 / s.f_sample_hz;
  const double w = kTwoPi * s.f_injection_hz;
  const size_t m = static_cast<size_t>(std::llround(s.f_sample_hz / (2.0 * s.f_injection_hz)));
  const size_t p = static_cast<size_t>(std::llround(s.f_sample_hz / s.f_injection_hz));
  if (m < 1 || s.n < 2 * m + 3 * p) {
    return absl::InvalidArgumentError(absl::StrCat(
        "field 't_s': ", s.n, " samples are too few for the delay filters (need ",
        2 * m + 3 * p, ")"));
  }
  // Delay filters valid from k0 = 2M; whole injection periods after that.
  const size_t k0 = 2 * m;
  const size_t periods = (s.n - k0) / p;
  const size_t k1 = k0 + periods * p;
  out.samples_used = k1 - k0;
  out.periods_used = static_cast<double>(periods);
  out.w_e_rad_s = EstimateSpeedRadPerS(s.theta_e_rad, s.n, s.f_sample_hz);
  const double w2 = 2.0 * out.w_e_rad_s - w;   // negative-sequence frequency
  const double tau = static_cast<double>(m) * ts;
  auto H = [&](double freq) { return Complex(1.0) - std::exp(Complex(0.0, -freq * tau)); };
  const Complex h0 = H(w) * H(w);
  const Complex g0 = compensate ? h0 : Complex(4.0);
  const Complex g1 = compensate ? H(w2) * H(w2) : Complex(4.0);

  // The pipeline is linear, so it is evaluated in one pass as weighted sums:
  //   y_k  = x_k - 2 x_{k-M} + x_{k-2M}              (two delay filters)
  //   LPF  = moving average over one period; phasor = mean of the LPF output
  //        = sum_k w_k z_k with w_k = (number of full windows holding k)/(P L)
  //   I0'  = sum w_k y_k conj(b0_k),   b0 = e^{j w t}
  //   I1'  = sum w_k (y_k - h0 I0 b0_k) conj(b1_k),   b1 = e^{j(2 theta - w t)}
  // i.e. exactly the cascade of docs/identification.md Sec. 4, without
  // storing intermediate signals (sums in demod_kernels.h).
  const size_t lpf_outputs = (k1 - k0) - p + 1;
  const double wnorm = 1.0 / (static_cast<double>(p) * static_cast<double>(lpf_outputs));
  const kernels::PhaseArrays arrays{s.ia_a, s.ib_a, s.ic_a, s.theta_e_rad, s.n};
  const kernels::PaperSums sums =
      kernels::PaperFilterSums(arrays, m, p, k0, periods, w * ts, kernels::BestIsa());
  auto c = [](const double* v) { return Complex(v[0], v[1]); };
  const Complex i0 = wnorm * c(sums.a0) / g0;
  // High-pass: remove the positive sequence as it appears after the filters.
  const Complex h0_used = compensate ? g0 : h0;
  const Complex i1 = wnorm * (c(sums.a1) - h0_used * i0 * c(sums.c01)) / g1;
  // Standard errors from the scatter of per-period (batch) means.
  auto batch_var = [&](auto value, Complex gain) {
    Complex mean = 0;
    for (size_t b = 0; b < periods; ++b) mean += value(b);
    mean /= static_cast<double>(periods);
    double v = 0;
    for (size_t b = 0; b < periods; ++b) v += std::norm(value(b) - mean);
    v /= static_cast<double>(periods > 1 ? periods - 1 : 1);
    return v / static_cast<double>(periods) / std::norm(gain);
  };
  const double pp = static_cast<double>(p);
  out.var_i0_a2 = batch_var([&](size_t b) { return c(&sums.z0[2 * b]) / pp; }, g0);
  out.var_i1_a2 = batch_var(
      [&](size_t b) { return (c(&sums.z1[2 * b]) - h0_used * i0 * c(&sums.x01[2 * b])) / pp; },
      g1);
  out.i0_a = i0;
  out.i1_a = i1;
  return out;
}

absl::StatusOr<VoltageEstimate> FitCommandVoltage(const double* ualpha_v, const double* ubeta_v,
                                                  const double* theta_e_rad, size_t n_total,
                                                  double f_sample_hz, double f_injection_hz) {
  double periods = 0;
  const size_t n = WholePeriodSamples(n_total, f_sample_hz, f_injection_hz, &periods);
  if (periods < 1) return absl::InvalidArgumentError("field 'ualpha_ref_v': too few samples");
  const double ts = 1.0 / f_sample_hz;
  const double w = kTwoPi * f_injection_hz;
  const double t_mid = 0.5 * static_cast<double>(n - 1) * ts;
  // Regressors: e^{jwt}, e^{j(2theta - wt)}, e^{jtheta}, tau e^{jtheta} (the
  // current's (D1)). At standstill the second is e^{-jwt} times a constant.
  Eigen::Matrix4cd G = Eigen::Matrix4cd::Zero();
  Eigen::Vector4cd h = Eigen::Vector4cd::Zero();
  for (size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * ts;
    const Complex et = std::polar(1.0, theta_e_rad[k]);
    const Eigen::Vector4cd b(std::polar(1.0, w * t), std::polar(1.0, 2.0 * theta_e_rad[k] - w * t), et,
                             (t - t_mid) * et);
    G.noalias() += b.conjugate() * b.transpose();
    h.noalias() += b.conjugate() * Complex(ualpha_v[k], ubeta_v[k]);
  }
  Eigen::LDLT<Eigen::Matrix4cd> ldlt(G);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
    return absl::InvalidArgumentError("field 'theta_e_rad': command regressors are degenerate "
                                      "(2 w_e too close to w_i?)");
  }
  const Eigen::Vector4cd x = ldlt.solve(h);
  return VoltageEstimate{x(0), x(1), x(2)};
}

Complex EffectiveVoltage(Complex v_cmd_v, double w_rad_s, double f_pwm_hz) {
  const double T = 1.0 / f_pwm_hz;
  return v_cmd_v * std::polar(1.0 / physics::ZohGain(w_rad_s, T), -physics::ControlDelayAngle(w_rad_s, T));
}

}  // namespace fluxcal::ident
