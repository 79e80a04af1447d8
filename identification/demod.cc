#include "identification/demod.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include <Eigen/Dense>

#include "absl/strings/str_cat.h"
#include "identification/fast_trig.h"

namespace fluxcal::ident {
namespace {

constexpr double kSqrt3 = 1.7320508075688772935;
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
  // Unwrap, then least-squares slope against the sample index.
  double prev = theta[0], offset = 0.0;
  double sx = 0, sy = 0, sxx = 0, sxy = 0;
  for (size_t k = 0; k < n; ++k) {
    double th = theta[k] + offset;
    const double d = th - prev;
    if (d > std::numbers::pi) { offset -= kTwoPi; th -= kTwoPi; }
    else if (d < -std::numbers::pi) { offset += kTwoPi; th += kTwoPi; }
    prev = th;
    const double x = static_cast<double>(k);
    sx += x; sy += th; sxx += x * x; sxy += x * th;
  }
  const double nn = static_cast<double>(n);
  const double slope = (nn * sxy - sx * sy) / (nn * sxx - sx * sx);
  return slope * f_sample_hz;
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

  // Normal equations G x = h for the four complex regressors
  //   b0 = e^{jwt}, b1 = e^{j2theta} e^{-jwt}, b2 = e^{jtheta}, b3 = tau e^{jtheta},
  // G_ij = sum conj(b_i) b_j, h_i = sum conj(b_i) y. Written in real
  // arithmetic (std::complex multiplication would add NaN checks per sample).
  // |b0| = |b1| = |b2| = 1, so G00 = G11 = G22 = n and G33 = sum tau^2.
  double g01r = 0, g01i = 0, g02r = 0, g02i = 0, g03r = 0, g03i = 0;
  double g12r = 0, g12i = 0, g13r = 0, g13i = 0, g23 = 0, g33 = 0;
  double h0r = 0, h0i = 0, h1r = 0, h1i = 0, h2r = 0, h2i = 0, h3r = 0, h3i = 0;
  double yy = 0;
  const double cw = std::cos(w * ts), sw = std::sin(w * ts);
  double pr = 1.0, pi = 0.0;  // e^{jwt} by recurrence, resynchronised below
  double last_theta = std::nan(""), st = 0, ct = 1, c2 = 1, s2 = 0;
  AngleRotor rotor;
  for (size_t k = 0; k < n; ++k) {
    if ((k & 1023) == 0) FastSinCos(w * ts * static_cast<double>(k), &pi, &pr);
    const double yr = (2.0 * s.ia_a[k] - s.ib_a[k] - s.ic_a[k]) * (1.0 / 3.0);
    const double yi = (s.ib_a[k] - s.ic_a[k]) * (1.0 / kSqrt3);
    if (s.theta_e_rad[k] != last_theta) {   // a locked rotor reads one count: reuse
      rotor.Next(s.theta_e_rad[k], &st, &ct);
      c2 = ct * ct - st * st;   // e^{j2theta}
      s2 = 2.0 * ct * st;
      last_theta = s.theta_e_rad[k];
    }
    // b1 = e^{j2theta} conj(p)
    const double b1r = c2 * pr + s2 * pi, b1i = s2 * pr - c2 * pi;
    const double tau = static_cast<double>(k) * ts - t_mid;
    // conj(b0) b1
    g01r += pr * b1r + pi * b1i;  g01i += pr * b1i - pi * b1r;
    // conj(b0) b2
    const double c02r = pr * ct + pi * st, c02i = pr * st - pi * ct;
    g02r += c02r;  g02i += c02i;
    g03r += tau * c02r;  g03i += tau * c02i;
    // conj(b1) b2
    const double c12r = b1r * ct + b1i * st, c12i = b1r * st - b1i * ct;
    g12r += c12r;  g12i += c12i;
    g13r += tau * c12r;  g13i += tau * c12i;
    g23 += tau;  g33 += tau * tau;
    // conj(b) y
    h0r += pr * yr + pi * yi;   h0i += pr * yi - pi * yr;
    h1r += b1r * yr + b1i * yi; h1i += b1r * yi - b1i * yr;
    const double h2rk = ct * yr + st * yi, h2ik = ct * yi - st * yr;
    h2r += h2rk;  h2i += h2ik;
    h3r += tau * h2rk;  h3i += tau * h2ik;
    yy += yr * yr + yi * yi;
    const double npr = pr * cw - pi * sw;
    pi = pr * sw + pi * cw;
    pr = npr;
  }
  const double nn = static_cast<double>(n);
  Eigen::Matrix4cd G;
  G(0, 0) = nn; G(1, 1) = nn; G(2, 2) = nn; G(3, 3) = g33;
  G(0, 1) = Complex(g01r, g01i); G(0, 2) = Complex(g02r, g02i); G(0, 3) = Complex(g03r, g03i);
  G(1, 2) = Complex(g12r, g12i); G(1, 3) = Complex(g13r, g13i); G(2, 3) = g23;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < i; ++j) G(i, j) = std::conj(G(j, i));
  Eigen::Vector4cd h(Complex(h0r, h0i), Complex(h1r, h1i), Complex(h2r, h2i), Complex(h3r, h3i));
  Eigen::LDLT<Eigen::Matrix4cd> ldlt(G);
  if (ldlt.info() != Eigen::Success || !ldlt.isPositive()) {
    return absl::InvalidArgumentError("field 'theta_e_rad': regressors are degenerate "
                                      "(2 w_e too close to w_i?)");
  }
  const Eigen::Vector4cd x = ldlt.solve(h);
  const Eigen::Matrix4cd Ginv = ldlt.solve(Eigen::Matrix4cd::Identity());
  // Residual sum of squares from the normal equations: RSS = y^H y - x^H h.
  const double rss = std::max(0.0, yy - (x.adjoint() * h)(0).real());
  const double sigma2 = rss / std::max(1.0, nn - 4.0);  // E|noise|^2 per sample
  out.i0_a = x(0);
  out.i1_a = x(1);
  out.fundamental_dq_a = x(2);
  out.fundamental_drift_a_per_s = x(3);
  out.var_i0_a2 = sigma2 * Ginv(0, 0).real();
  out.var_i1_a2 = sigma2 * Ginv(1, 1).real();
  out.cov_i0_i1_a2 = sigma2 * Ginv(0, 1);
  out.residual_rms_a = std::sqrt(rss / nn);
  out.w_e_rad_s = EstimateSpeedRadPerS(s.theta_e_rad, n, s.f_sample_hz);
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
  // storing intermediate signals.
  const size_t lpf_outputs = (k1 - k0) - p + 1;
  const double wnorm = 1.0 / (static_cast<double>(p) * static_cast<double>(lpf_outputs));
  auto clarke = [&](size_t k) {
    return Complex((2.0 * s.ia_a[k] - s.ib_a[k] - s.ic_a[k]) * (1.0 / 3.0),
                   (s.ib_a[k] - s.ic_a[k]) * (1.0 / kSqrt3));
  };
  double a0r = 0, a0i = 0, a1r = 0, a1i = 0, c01r = 0, c01i = 0;
  std::vector<Complex> bz0(periods), bz1(periods), bb01(periods);
  const double cw = std::cos(w * ts), sw = std::sin(w * ts);
  double pr = 0, pi = 0;
  double last_theta = std::nan(""), c2 = 1, s2 = 0;
  AngleRotor rotor;
  size_t batch = 0, in_batch = 0;
  for (size_t k = k0; k < k1; ++k) {
    if (((k - k0) & 1023) == 0) FastSinCos(w * ts * static_cast<double>(k), &pi, &pr);
    const Complex y = clarke(k) - 2.0 * clarke(k - m) + clarke(k - 2 * m);
    const double th = s.theta_e_rad[k];
    if (th != last_theta) {   // a locked rotor reads the same count: reuse
      double st, ct;
      rotor.Next(th, &st, &ct);
      c2 = ct * ct - st * st;
      s2 = 2.0 * ct * st;
      last_theta = th;
    }
    // b1 = e^{j 2 theta} conj(b0)
    const double b1r = c2 * pr + s2 * pi, b1i = s2 * pr - c2 * pi;
    const size_t r = k - k0;
    const double wk = static_cast<double>(std::min({r + 1, static_cast<size_t>(p), k1 - k, lpf_outputs})) * wnorm;
    // y conj(b0), y conj(b1), b0 conj(b1)
    const double z0r = y.real() * pr + y.imag() * pi, z0i = y.imag() * pr - y.real() * pi;
    const double z1r = y.real() * b1r + y.imag() * b1i, z1i = y.imag() * b1r - y.real() * b1i;
    const double x01r = pr * b1r + pi * b1i, x01i = pi * b1r - pr * b1i;
    a0r += wk * z0r; a0i += wk * z0i;
    a1r += wk * z1r; a1i += wk * z1i;
    c01r += wk * x01r; c01i += wk * x01i;
    bz0[batch] += Complex(z0r, z0i);
    bz1[batch] += Complex(z1r, z1i);
    bb01[batch] += Complex(x01r, x01i);
    if (++in_batch == p) { in_batch = 0; ++batch; }
    const double npr = pr * cw - pi * sw;
    pi = pr * sw + pi * cw;
    pr = npr;
  }
  const Complex i0 = Complex(a0r, a0i) / g0;
  // High-pass: remove the positive sequence as it appears after the filters.
  const Complex h0_used = compensate ? g0 : h0;
  const Complex i1 = (Complex(a1r, a1i) - h0_used * i0 * Complex(c01r, c01i)) / g1;
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
  out.var_i0_a2 = batch_var([&](size_t b) { return bz0[b] / pp; }, g0);
  out.var_i1_a2 = batch_var([&](size_t b) { return (bz1[b] - h0_used * i0 * bb01[b]) / pp; }, g1);
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
  // Regressors: e^{jwt}, e^{-jwt}, e^{jtheta}, tau e^{jtheta}.
  Eigen::Matrix4cd G = Eigen::Matrix4cd::Zero();
  Eigen::Vector4cd h = Eigen::Vector4cd::Zero();
  for (size_t k = 0; k < n; ++k) {
    const double t = static_cast<double>(k) * ts;
    const Complex et = std::polar(1.0, theta_e_rad[k]);
    const Eigen::Vector4cd b(std::polar(1.0, w * t), std::polar(1.0, -w * t), et,
                             (t - t_mid) * et);
    G.noalias() += b.conjugate() * b.transpose();
    h.noalias() += b.conjugate() * Complex(ualpha_v[k], ubeta_v[k]);
  }
  const Eigen::Vector4cd x = G.ldlt().solve(h);
  return VoltageEstimate{x(0), x(2)};
}

Complex EffectiveVoltage(Complex v_cmd_v, double w_rad_s, double f_pwm_hz) {
  const double T = 1.0 / f_pwm_hz;
  const double xx = 0.5 * w_rad_s * T;
  const double gain = std::abs(xx) < 1e-12 ? 1.0 : xx / std::sin(xx);
  return v_cmd_v * std::polar(gain, -1.5 * w_rad_s * T);
}

}  // namespace fluxcal::ident
