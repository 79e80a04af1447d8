// The vectorised demodulator kernels against plain std::complex reference
// sums, for every instruction set this CPU runs (the baseline always; AVX2
// and AVX-512 where present), on lengths and periods that are not multiples
// of any vector width, with wrapped quantised angles at speed.
#include "identification/demod_kernels.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <numbers>
#include <random>
#include <vector>

#include "gtest/gtest.h"

namespace fluxcal::ident::kernels {
namespace {

using Complex = std::complex<double>;
constexpr double kPi = std::numbers::pi;

std::vector<Isa> Supported() {
  std::vector<Isa> out;
  for (Isa isa : {Isa::kBaseline, Isa::kAvx2, Isa::kAvx512})
    if (IsaSupported(isa)) out.push_back(isa);
  return out;
}

struct Record {
  std::vector<double> ia, ib, ic, th;
  PhaseArrays View() const { return {ia.data(), ib.data(), ic.data(), th.data(), ia.size()}; }
};

// Rotating injection plus fundamental plus noise; the angle wrapped to
// (-pi, pi] and quantised like a 4096-count encoder on 4 pole pairs.
Record MakeRecord(size_t n, double w_ts, double we_ts) {
  Record r;
  std::mt19937_64 rng(7);
  std::normal_distribution<double> nd(0, 0.05);
  const double count = 2 * kPi * 4 / 4096;
  for (size_t k = 0; k < n; ++k) {
    const double th = 0.4 + we_ts * static_cast<double>(k);
    const double wt = w_ts * static_cast<double>(k);
    const Complex i = 6.0 * std::polar(1.0, wt) + Complex(1.5, -0.8) * std::polar(1.0, 2 * th - wt) +
                      Complex(-20, 35) * std::polar(1.0, th);
    r.ia.push_back(i.real() + nd(rng));
    r.ib.push_back(-0.5 * i.real() + std::sqrt(3.0) / 2 * i.imag() + nd(rng));
    r.ic.push_back(-0.5 * i.real() - std::sqrt(3.0) / 2 * i.imag() + nd(rng));
    r.th.push_back(std::remainder(std::round(th / count) * count, 2 * kPi));
  }
  return r;
}

Complex Clarke(const Record& r, size_t k) {
  return Complex((2 * r.ia[k] - r.ib[k] - r.ic[k]) / 3.0, (r.ib[k] - r.ic[k]) / std::sqrt(3.0));
}

void ExpectClose(const double* got, Complex want, double scale, const char* what, Isa isa) {
  EXPECT_LT(std::abs(Complex(got[0], got[1]) - want), 1e-12 * scale)
      << what << " (" << IsaName(isa) << "): " << got[0] << " + j" << got[1] << ", want " << want;
}

TEST(DemodKernels, SinCosMatchesStdOnEveryIsa) {
  std::vector<double> x;
  for (double v = -1000; v < 1000; v += 0.0137) x.push_back(v);
  for (double v = -1e5; v < 1e5; v += 77.7) x.push_back(v);
  x.push_back(0.0);
  x.push_back(kPi / 4);
  x.push_back(-kPi / 2);
  for (Isa isa : Supported()) {
    std::vector<double> s(x.size()), c(x.size());
    SinCos(x.data(), x.size(), s.data(), c.data(), isa);
    double worst = 0;
    for (size_t i = 0; i < x.size(); ++i)
      worst = std::max({worst, std::abs(s[i] - std::sin(x[i])), std::abs(c[i] - std::cos(x[i]))});
    EXPECT_LT(worst, 1e-13) << IsaName(isa) << ": largest deviation from std::sin/cos";
  }
}

TEST(DemodKernels, LsqSumsMatchReferenceOnEveryIsa) {
  const double fs = 10000, fi = 700, ts = 1 / fs, w_ts = 2 * kPi * fi * ts;
  for (double we_ts : {0.0, 0.0419, -0.09}) {
    const Record r = MakeRecord(1003, w_ts, we_ts);
    const size_t n = 997;   // fewer than the arrays hold: the kernel must stop at n
    const double t_mid = 0.5 * (n - 1) * ts;
    Complex g01, g02, g03, h0, h1, h2, h3;
    double yy = 0;
    for (size_t k = 0; k < n; ++k) {
      const Complex p = std::polar(1.0, w_ts * k), e = std::polar(1.0, r.th[k]), y = Clarke(r, k);
      const double tau = k * ts - t_mid;
      g01 += e * e * std::conj(p * p);
      g02 += e * std::conj(p);
      g03 += tau * e * std::conj(p);
      h0 += std::conj(p) * y;
      h1 += std::conj(e * e) * p * y;
      h2 += std::conj(e) * y;
      h3 += tau * std::conj(e) * y;
      yy += std::norm(y);
    }
    for (Isa isa : Supported()) {
      const LsqSums got = LsqNormalSums(r.View(), n, w_ts, t_mid, ts, isa);
      const double scale = n * 50.0;
      ExpectClose(got.g01, g01, n, "g01", isa);
      ExpectClose(got.g02, g02, n, "g02", isa);
      ExpectClose(got.g03, g03, n * t_mid, "g03", isa);
      ExpectClose(got.h0, h0, scale, "h0", isa);
      ExpectClose(got.h1, h1, scale, "h1", isa);
      ExpectClose(got.h2, h2, scale, "h2", isa);
      ExpectClose(got.h3, h3, scale * t_mid, "h3", isa);
      EXPECT_NEAR(got.yy, yy, 1e-12 * yy) << IsaName(isa);
    }
  }
}

// The residual's sums (ResidualSumsOf) against std::complex sums of the
// definition in demod_kernels.h, with a model that leaves a residual of
// the noise plus a misfit of each term, sidebands on and off.
TEST(DemodKernels, ResidualSumsMatchReferenceOnEveryIsa) {
  const double fs = 10000, fi = 700, ts = 1 / fs, w_ts = 2 * kPi * fi * ts;
  for (double we_ts : {0.0, 0.0419, -0.09}) {
    const Record r = MakeRecord(1003, w_ts, we_ts);
    const size_t n = 997;   // fewer than the arrays hold: the kernel must stop at n
    const double t_mid = 0.5 * (n - 1) * ts;
    const Complex i0(5.9, 0.05), i1(1.4, -0.75), c0(-19.9, 35.1), c1(3.0, -2.0);
    const double model[8] = {i0.real(), i0.imag(), i1.real(), i1.imag(), c0.real(), c0.imag(), c1.real(), c1.imag()};
    constexpr int kB = 2 * kResidualBins;
    Complex bins0[kB], bins1[kB], side0[4], side1[4], harm[5];
    const int orders[4] = {-12, -6, 6, 12}, injection[5] = {-1, 3, -3, 5, -5};
    for (size_t k = 0; k < n; ++k) {
      const Complex p = std::polar(1.0, w_ts * k), e = std::polar(1.0, r.th[k]), y = Clarke(r, k);
      const double tau = k * ts - t_mid;
      const Complex b1 = e * e * std::conj(p);
      const Complex res = y - i0 * p - i1 * b1 - (c0 + c1 * tau) * e;
      const Complex r0 = res * std::conj(p), r1 = res * std::conj(b1);
      for (int b = 0; b < kB; ++b) {
        const int q = b < kResidualBins ? b - kResidualBins : b - kResidualBins + 1;
        const Complex t = std::polar(1.0, -2 * kPi * q * static_cast<double>(k) / static_cast<double>(n));
        bins0[b] += r0 * t;
        bins1[b] += r1 * t;
      }
      for (int j = 0; j < 4; ++j) {
        side0[j] += r0 * std::polar(1.0, -orders[j] * r.th[k]);
        side1[j] += r1 * std::polar(1.0, -orders[j] * r.th[k]);
      }
      for (int h = 0; h < 5; ++h) harm[h] += res * std::polar(1.0, -injection[h] * w_ts * k);
    }
    for (Isa isa : Supported()) {
      for (bool sidebands : {false, true}) {
        const ResidualSums got = ResidualSumsOf(r.View(), n, w_ts, t_mid, ts, model, sidebands, isa);
        const double scale = n * 50.0;
        for (int b = 0; b < kB; ++b) {
          ExpectClose(got.bins0[b], bins0[b], scale, "bins0", isa);
          ExpectClose(got.bins1[b], bins1[b], scale, "bins1", isa);
        }
        for (int j = 0; j < 4; ++j) {
          ExpectClose(got.side0[j], sidebands ? side0[j] : Complex(), scale, "side0", isa);
          ExpectClose(got.side1[j], sidebands ? side1[j] : Complex(), scale, "side1", isa);
        }
        for (int h = 0; h < 5; ++h) ExpectClose(got.harm[h], harm[h], scale, "harm", isa);
      }
    }
  }
}

TEST(DemodKernels, PaperSumsMatchReferenceOnEveryIsa) {
  // P = 14 and M = 7 at 10 kHz / 700 Hz: no vector width divides the period.
  const double fs = 10000, fi = 700, w_ts = 2 * kPi * fi / fs;
  const size_t m = 7, p = 14, k0 = 2 * m;
  for (double we_ts : {0.0, 0.0419}) {
    const Record r = MakeRecord(k0 + 9 * p + 3, w_ts, we_ts);
    const size_t periods = 9, k_end = k0 + periods * p;
    Complex a0, a1, c01;
    std::vector<Complex> z0(periods), z1(periods), x01(periods);
    for (size_t k = k0; k < k_end; ++k) {
      const Complex y = Clarke(r, k) - 2.0 * Clarke(r, k - m) + Clarke(r, k - 2 * m);
      const Complex p_k = std::polar(1.0, w_ts * k), e = std::polar(1.0, r.th[k]);
      const Complex b1 = e * e * std::conj(p_k);
      const double v = static_cast<double>(std::min({k - k0 + 1, p, k_end - k}));
      const size_t b = (k - k0) / p;
      z0[b] += y * std::conj(p_k);
      z1[b] += y * std::conj(b1);
      x01[b] += p_k * std::conj(b1);
      a0 += v * y * std::conj(p_k);
      a1 += v * y * std::conj(b1);
      c01 += v * p_k * std::conj(b1);
    }
    for (Isa isa : Supported()) {
      const PaperSums got = PaperFilterSums(r.View(), m, p, k0, periods, w_ts, isa);
      ASSERT_EQ(got.z0.size(), 2 * periods);
      const double scale = 200.0 * p * (k_end - k0);
      ExpectClose(got.a0, a0, scale, "a0", isa);
      ExpectClose(got.a1, a1, scale, "a1", isa);
      ExpectClose(got.c01, c01, p * (k_end - k0), "c01", isa);
      for (size_t b = 0; b < periods; ++b) {
        ExpectClose(&got.z0[2 * b], z0[b], 200.0 * p, "z0", isa);
        ExpectClose(&got.z1[2 * b], z1[b], 200.0 * p, "z1", isa);
        ExpectClose(&got.x01[2 * b], x01[b], p, "x01", isa);
      }
    }
  }
}

TEST(DemodKernels, AngleSlopeEqualsLeastSquaresOnUnwrappedAngle) {
  for (double we_ts : {0.0, 0.0419, -0.3, 1.2}) {
    const Record r = MakeRecord(1001, 0.3, we_ts);
    // Reference: unwrap, then the least-squares slope against the index.
    std::vector<double> u(r.th);
    for (size_t k = 1; k < u.size(); ++k)
      u[k] = u[k - 1] + std::remainder(r.th[k] - r.th[k - 1], 2 * kPi);
    double sx = 0, sy = 0, sxx = 0, sxy = 0;
    const double nn = static_cast<double>(u.size());
    for (size_t k = 0; k < u.size(); ++k) {
      sx += k; sy += u[k]; sxx += double(k) * k; sxy += k * u[k];
    }
    const double want = (nn * sxy - sx * sy) / (nn * sxx - sx * sx);
    for (Isa isa : Supported()) {
      EXPECT_NEAR(AngleSlopeRadPerSample(r.th.data(), r.th.size(), isa), want,
                  1e-12 + 1e-10 * std::abs(want))
          << IsaName(isa) << " at " << we_ts << " rad/sample";
    }
  }
}

TEST(DemodKernels, BestIsaIsSupported) {
  EXPECT_TRUE(IsaSupported(BestIsa())) << IsaName(BestIsa());
  EXPECT_TRUE(IsaSupported(Isa::kBaseline));
}

}  // namespace
}  // namespace fluxcal::ident::kernels
