#include "identification/demod.h"

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
  for (size_t k = 0; k < n; ++k) {
    if ((k & 1023) == 0) FastSinCos(w * ts * static_cast<double>(k), &pi, &pr);
    const double yr = (2.0 * s.ia_a[k] - s.ib_a[k] - s.ic_a[k]) * (1.0 / 3.0);
    const double yi = (s.ib_a[k] - s.ic_a[k]) * (1.0 / kSqrt3);
    double st, ct;
    FastSinCos(s.theta_e_rad[k], &st, &ct);
    const double c2 = ct * ct - st * st, s2 = 2.0 * ct * st;  // e^{j2theta}
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
  const size_t n = s.n;
  std::vector<Complex> x(n), y(n);
  for (size_t k = 0; k < n; ++k) {
    x[k] = Complex((2.0 * s.ia_a[k] - s.ib_a[k] - s.ic_a[k]) / 3.0,
                   (s.ib_a[k] - s.ic_a[k]) / kSqrt3);
  }
  // Two cascaded delay filters D(x)_k = x_k - x_{k-M}; valid from k = 2M.
  for (size_t k = 2 * m; k < n; ++k) {
    y[k] = x[k] - 2.0 * x[k - m] + x[k - 2 * m];
  }
  const size_t k0 = 2 * m;
  // Whole injection periods after the delay-filter transient.
  const size_t periods = (n - k0) / p;
  const size_t k1 = k0 + periods * p;
  out.samples_used = k1 - k0;
  out.periods_used = static_cast<double>(periods);
  out.w_e_rad_s = EstimateSpeedRadPerS(s.theta_e_rad, n, s.f_sample_hz);
  const double w2 = 2.0 * out.w_e_rad_s - w;  // negative-sequence frequency
  const double tau = static_cast<double>(m) * ts;
  auto H = [&](double freq) { return Complex(1.0) - std::exp(Complex(0.0, -freq * tau)); };
  const Complex g0 = compensate ? H(w) * H(w) : Complex(4.0);
  const Complex g1 = compensate ? H(w2) * H(w2) : Complex(4.0);

  // Synchronous frame at +w_i, low-pass = moving average over one period;
  // the phasor is the mean of the low-pass output. With the moving average
  // over whole periods the mean of its output equals a triangular-weighted
  // mean of the demodulated signal; batch means over single periods give the
  // scatter for the standard error.
  auto demod = [&](auto basis, Complex gain, Complex* phasor, double* var) {
    std::vector<Complex> batch(periods);
    Complex lpf_sum = 0.0, lpf_mean = 0.0;
    Complex run = 0.0;
    size_t lpf_count = 0;
    for (size_t k = k0; k < k1; ++k) {
      const Complex z = y[k] * std::conj(basis(k));
      batch[(k - k0) / p] += z;
      run += z;
      if (k >= k0 + p) run -= y[k - p] * std::conj(basis(k - p));
      if (k + 1 >= k0 + p) {  // moving average full
        lpf_sum += run / static_cast<double>(p);
        ++lpf_count;
      }
    }
    lpf_mean = lpf_sum / static_cast<double>(lpf_count);
    *phasor = lpf_mean / gain;
    Complex bm = 0.0;
    for (auto& b : batch) { b /= static_cast<double>(p); bm += b; }
    bm /= static_cast<double>(periods);
    double v = 0.0;
    for (const auto& b : batch) v += std::norm(b - bm);
    v /= static_cast<double>(periods > 1 ? periods - 1 : 1);
    *var = v / static_cast<double>(periods) / std::norm(gain);
  };
  auto b0 = [&](size_t k) { return std::exp(Complex(0.0, w * ts * static_cast<double>(k))); };
  Complex i0;
  double var0 = 0;
  demod(b0, g0, &i0, &var0);
  // High-pass: remove the positive sequence (as it appears after the delay
  // filters) before the negative-sequence frame.
  const Complex i0_filtered = (compensate ? g0 : H(w) * H(w)) * i0;
  for (size_t k = k0; k < k1; ++k) y[k] -= i0_filtered * b0(k);
  auto b1 = [&](size_t k) {
    return std::exp(Complex(0.0, 2.0 * s.theta_e_rad[k] - w * ts * static_cast<double>(k)));
  };
  Complex i1;
  double var1 = 0;
  demod(b1, g1, &i1, &var1);
  out.i0_a = i0;
  out.i1_a = i1;
  out.var_i0_a2 = var0;
  out.var_i1_a2 = var1;
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
