#include "identification/demod_kernels.h"

#include <cmath>
#include <cstring>
#include <numbers>

// The kernels pass GCC vector types between always-inline helpers only; the
// ABI note about passing them by value does not concern this file.
#pragma GCC diagnostic ignored "-Wpsabi"

#if defined(__GNUC__) && defined(__x86_64__)
#define FLUXCAL_X86_DISPATCH 1
#define FLUXCAL_TARGET_AVX2 __attribute__((target("avx2,fma")))
#define FLUXCAL_TARGET_AVX512 __attribute__((target("avx2,fma,avx512f,avx512vl,avx512dq")))
#endif

#define FLUXCAL_INLINE inline __attribute__((always_inline))

namespace fluxcal::ident::kernels {
namespace {

constexpr double kSqrt3 = 1.7320508075688772935;
constexpr double kTwoPi = 2.0 * std::numbers::pi;
// 1.5 * 2^52: for |x| < 2^51, x + kRound lands in [2^52, 2^53) where the
// spacing of doubles is 1, so the sum is x rounded to the nearest integer and
// its low mantissa bits hold that integer (two's complement modulo 2^51).
constexpr double kRound = 6755399441055744.0;

// W doubles in one GCC vector (lowered to SSE2, AVX2 or AVX-512 registers by
// the target of the function it is inlined into).
template <int W>
struct Vec {
  typedef double D __attribute__((vector_size(8 * W)));
  typedef unsigned long long U __attribute__((vector_size(8 * W)));
};

template <int W>
FLUXCAL_INLINE typename Vec<W>::D Load(const double* p) {
  typename Vec<W>::D v;
  std::memcpy(&v, p, sizeof v);
  return v;
}

// Loads lanes p[0..count) and zero-fills the rest (never reads past count).
template <int W>
FLUXCAL_INLINE typename Vec<W>::D LoadPartial(const double* p, size_t count) {
  double buf[W] = {};
  for (size_t i = 0; i < count && i < static_cast<size_t>(W); ++i) buf[i] = p[i];
  return Load<W>(buf);
}

template <int W>
FLUXCAL_INLINE typename Vec<W>::D Iota() {
  typename Vec<W>::D v;
  for (int i = 0; i < W; ++i) v[i] = i;
  return v;
}

template <int W>
FLUXCAL_INLINE double HorizontalSum(typename Vec<W>::D v) {
  double s = 0;
  for (int i = 0; i < W; ++i) s += v[i];
  return s;
}

template <int W>
FLUXCAL_INLINE void PutComplex(double* dst, typename Vec<W>::D re, typename Vec<W>::D im) {
  dst[0] = HorizontalSum<W>(re);
  dst[1] = HorizontalSum<W>(im);
}

template <int W>
FLUXCAL_INLINE typename Vec<W>::D Min(typename Vec<W>::D a, typename Vec<W>::D b) {
  return a < b ? a : b;
}

// sin and cos per lane. Range reduction by the nearest multiple q of pi/2
// (Cody-Waite with pi/2 split in three 33-bit parts, fdlibm's e_rem_pio2.c:
// q times each part is exact for |q| < 2^20, with or without fused
// multiply-adds), then Taylor polynomials on |r| <= pi/4
// to degree 15 (sin) and 16 (cos): truncation < (pi/4)^17/17! ~ 5e-17, so
// the result matches std::sin/cos to a few ulp for |x| < 1e6 rad
// (tests/identification/kernels_test.cc). The quadrant is selected with bit
// operations, without branches: at speed it changes every few samples.
template <int W>
FLUXCAL_INLINE void SinCosV(typename Vec<W>::D x, typename Vec<W>::D* s, typename Vec<W>::D* c) {
  using D = typename Vec<W>::D;
  using U = typename Vec<W>::U;
  constexpr double kTwoOverPi = 0.63661977236758134308;
  constexpr double kPiOver2A = 1.57079632673412561417e+00;
  constexpr double kPiOver2B = 6.07710050630396597660e-11;
  constexpr double kPiOver2C = 2.02226624871116645580e-21;
  const D t = x * kTwoOverPi + kRound;
  const D q = t - kRound;
  const U quadrant = (U)t;   // low two bits: q mod 4
  const D r = ((x - q * kPiOver2A) - q * kPiOver2B) - q * kPiOver2C;
  const D r2 = r * r;
  const D sr =
      r + r * r2 * (-1.0 / 6 + r2 * (1.0 / 120 + r2 * (-1.0 / 5040 + r2 * (1.0 / 362880 +
          r2 * (-1.0 / 39916800 + r2 * (1.0 / 6227020800.0 + r2 * (-1.0 / 1307674368000.0)))))));
  const D cr =
      1.0 + r2 * (-0.5 + r2 * (1.0 / 24 + r2 * (-1.0 / 720 + r2 * (1.0 / 40320 +
          r2 * (-1.0 / 3628800 + r2 * (1.0 / 479001600.0 + r2 * (-1.0 / 87178291200.0 +
          r2 * (1.0 / 20922789888000.0))))))));
  // Quadrant 0: (sr, cr); 1: (cr, -sr); 2: (-sr, -cr); 3: (-cr, sr).
  const U swap = -(quadrant & 1);   // all ones in odd quadrants
  const U sb = ((U)sr & ~swap) | ((U)cr & swap);
  const U cb = ((U)cr & ~swap) | ((U)sr & swap);
  *s = (D)(sb ^ ((quadrant & 2) << 62));
  *c = (D)(cb ^ (((quadrant + 1) & 2) << 62));
}

// p_k = e^{j w Ts k} for lanes k = k_first + i, exactly.
template <int W>
FLUXCAL_INLINE void InjectionPhasor(double w_ts, size_t k_first, typename Vec<W>::D* pr,
                                    typename Vec<W>::D* pi) {
  SinCosV<W>((Iota<W>() + static_cast<double>(k_first)) * w_ts, pi, pr);
}

// Between exact evaluations the injection phasor advances by a complex
// multiplication per vector; after kResync steps the accumulated rounding is
// below 1e-14 and it is evaluated afresh.
constexpr size_t kResync = 32;

// ---------------------------------------------------------------- lsq

template <int W>
struct LsqAcc {
  using D = typename Vec<W>::D;
  D g01r{}, g01i{}, g02r{}, g02i{}, g03r{}, g03i{};
  D h0r{}, h0i{}, h1r{}, h1i{}, h2r{}, h2i{}, h3r{}, h3i{}, yy{};
};

// One vector of samples into the sums of LsqSums. `valid` (1 or 0 per lane)
// zeroes padded lanes: with y = 0 and e = 0 every product vanishes.
template <int W, bool kMasked>
FLUXCAL_INLINE void LsqStep(LsqAcc<W>& a, typename Vec<W>::D ia, typename Vec<W>::D ib,
                            typename Vec<W>::D ic, typename Vec<W>::D th, typename Vec<W>::D tau,
                            typename Vec<W>::D pr, typename Vec<W>::D pi, typename Vec<W>::D valid) {
  using D = typename Vec<W>::D;
  // Amplitude-invariant Clarke transform.
  const D yr = (2.0 * ia - ib - ic) * (1.0 / 3.0);
  const D yi = (ib - ic) * (1.0 / kSqrt3);
  D st, ct;
  SinCosV<W>(th, &st, &ct);
  if constexpr (kMasked) {
    st *= valid;
    ct *= valid;
  }
  const D c2 = ct * ct - st * st, s2 = 2.0 * ct * st;          // e^{j 2 theta}
  const D q2r = pr * pr - pi * pi, q2i = -2.0 * pr * pi;       // conj(p)^2
  a.g01r += c2 * q2r - s2 * q2i;
  a.g01i += c2 * q2i + s2 * q2r;
  const D c02r = ct * pr + st * pi, c02i = st * pr - ct * pi;  // e conj(p)
  a.g02r += c02r;
  a.g02i += c02i;
  a.g03r += tau * c02r;
  a.g03i += tau * c02i;
  a.h0r += pr * yr + pi * yi;                                  // conj(p) y
  a.h0i += pr * yi - pi * yr;
  const D b1r = c2 * pr + s2 * pi, b1i = s2 * pr - c2 * pi;    // b1 = e^2 conj(p)
  a.h1r += b1r * yr + b1i * yi;                                // conj(b1) y
  a.h1i += b1r * yi - b1i * yr;
  const D ur = ct * yr + st * yi, ui = ct * yi - st * yr;      // conj(e) y
  a.h2r += ur;
  a.h2i += ui;
  a.h3r += tau * ur;
  a.h3i += tau * ui;
  a.yy += yr * yr + yi * yi;
}

template <int W>
FLUXCAL_INLINE LsqSums LsqKernel(const PhaseArrays& in, size_t n, double w_ts, double t_mid,
                                 double ts) {
  using D = typename Vec<W>::D;
  LsqAcc<W> a;
  const D iota = Iota<W>();
  const double step_c = std::cos(w_ts * W), step_s = std::sin(w_ts * W);
  D pr{}, pi{}, ones = iota * 0.0 + 1.0;
  size_t k = 0, it = 0;
  for (; k + W <= n; k += W, ++it) {
    if (it % kResync == 0) InjectionPhasor<W>(w_ts, k, &pr, &pi);
    const D tau = (iota + static_cast<double>(k)) * ts - t_mid;
    LsqStep<W, false>(a, Load<W>(in.ia_a + k), Load<W>(in.ib_a + k), Load<W>(in.ic_a + k),
                      Load<W>(in.theta_e_rad + k), tau, pr, pi, ones);
    const D npr = pr * step_c - pi * step_s;
    pi = pr * step_s + pi * step_c;
    pr = npr;
  }
  if (k < n) {
    const size_t rest = n - k;
    InjectionPhasor<W>(w_ts, k, &pr, &pi);
    const D tau = (iota + static_cast<double>(k)) * ts - t_mid;
    const D valid = iota < static_cast<double>(rest) ? ones : ones * 0.0;
    LsqStep<W, true>(a, LoadPartial<W>(in.ia_a + k, rest), LoadPartial<W>(in.ib_a + k, rest),
                     LoadPartial<W>(in.ic_a + k, rest), LoadPartial<W>(in.theta_e_rad + k, rest),
                     tau, pr, pi, valid);
  }
  LsqSums out;
  PutComplex<W>(out.g01, a.g01r, a.g01i);
  PutComplex<W>(out.g02, a.g02r, a.g02i);
  PutComplex<W>(out.g03, a.g03r, a.g03i);
  PutComplex<W>(out.h0, a.h0r, a.h0i);
  PutComplex<W>(out.h1, a.h1r, a.h1i);
  PutComplex<W>(out.h2, a.h2r, a.h2i);
  PutComplex<W>(out.h3, a.h3r, a.h3i);
  out.yy = HorizontalSum<W>(a.yy);
  return out;
}

// -------------------------------------------------------------- paper

template <int W>
struct PaperAcc {
  using D = typename Vec<W>::D;
  D a0r{}, a0i{}, a1r{}, a1i{}, c01r{}, c01i{};   // weighted, whole window
  D z0r{}, z0i{}, z1r{}, z1i{}, x01r{}, x01i{};   // unweighted, one period
};

template <int W, bool kPartial>
FLUXCAL_INLINE typename Vec<W>::D LoadMaybePartial(const double* x, size_t count) {
  if constexpr (kPartial) return LoadPartial<W>(x, count);
  return Load<W>(x);
}

template <int W, bool kPartialLoad, bool kMasked>
FLUXCAL_INLINE void PaperStep(PaperAcc<W>& a, const PhaseArrays& in, size_t k, size_t m,
                              size_t count, typename Vec<W>::D weight, typename Vec<W>::D pr,
                              typename Vec<W>::D pi, typename Vec<W>::D valid) {
  using D = typename Vec<W>::D;
  // Two cascaded delay filters D(x)_k = x_k - x_{k-M} on each phase current,
  // then the Clarke transform (both linear, so their order does not matter).
  const D da = LoadMaybePartial<W, kPartialLoad>(in.ia_a + k, count) - 2.0 * LoadMaybePartial<W, kPartialLoad>(in.ia_a + k - m, count) + LoadMaybePartial<W, kPartialLoad>(in.ia_a + k - 2 * m, count);
  const D db = LoadMaybePartial<W, kPartialLoad>(in.ib_a + k, count) - 2.0 * LoadMaybePartial<W, kPartialLoad>(in.ib_a + k - m, count) + LoadMaybePartial<W, kPartialLoad>(in.ib_a + k - 2 * m, count);
  const D dc = LoadMaybePartial<W, kPartialLoad>(in.ic_a + k, count) - 2.0 * LoadMaybePartial<W, kPartialLoad>(in.ic_a + k - m, count) + LoadMaybePartial<W, kPartialLoad>(in.ic_a + k - 2 * m, count);
  D yr = (2.0 * da - db - dc) * (1.0 / 3.0);
  D yi = (db - dc) * (1.0 / kSqrt3);
  D st, ct;
  SinCosV<W>(LoadMaybePartial<W, kPartialLoad>(in.theta_e_rad + k, count), &st, &ct);
  if constexpr (kMasked) {
    yr *= valid;
    yi *= valid;
    st *= valid;
    ct *= valid;
  }
  const D c2 = ct * ct - st * st, s2 = 2.0 * ct * st;          // e^{j 2 theta}
  const D b1r = c2 * pr + s2 * pi, b1i = s2 * pr - c2 * pi;    // b1 = e^2 conj(p)
  const D z0r = yr * pr + yi * pi, z0i = yi * pr - yr * pi;    // y conj(p)
  const D z1r = yr * b1r + yi * b1i, z1i = yi * b1r - yr * b1i;  // y conj(b1)
  const D x01r = pr * b1r + pi * b1i, x01i = pi * b1r - pr * b1i;  // p conj(b1)
  a.z0r += z0r;
  a.z0i += z0i;
  a.z1r += z1r;
  a.z1i += z1i;
  a.x01r += x01r;
  a.x01i += x01i;
  a.a0r += weight * z0r;
  a.a0i += weight * z0i;
  a.a1r += weight * z1r;
  a.a1i += weight * z1i;
  a.c01r += weight * x01r;
  a.c01i += weight * x01i;
}

// Number of one-period moving-average windows over [k0, k_end) that hold
// sample k (per lane): min(k - k0 + 1, P, k_end - k).
template <int W>
FLUXCAL_INLINE typename Vec<W>::D MovingAverageWeight(size_t k, size_t k0, size_t k_end,
                                                     typename Vec<W>::D period) {
  const typename Vec<W>::D kv = Iota<W>() + static_cast<double>(k);
  return Min<W>(Min<W>(kv - static_cast<double>(k0) + 1.0, period),
                static_cast<double>(k_end) - kv);
}

template <int W>
FLUXCAL_INLINE void PaperKernel(const PhaseArrays& in, size_t m, size_t p, size_t k0,
                                size_t periods, double w_ts, PaperSums* out) {
  using D = typename Vec<W>::D;
  out->z0.assign(2 * periods, 0.0);
  out->z1.assign(2 * periods, 0.0);
  out->x01.assign(2 * periods, 0.0);
  PaperAcc<W> a;
  const D iota = Iota<W>(), ones = iota * 0.0 + 1.0;
  const double step_c = std::cos(w_ts * W), step_s = std::sin(w_ts * W);
  const double period_c = std::cos(w_ts * static_cast<double>(p));
  const double period_s = std::sin(w_ts * static_cast<double>(p));
  const size_t k_end = k0 + periods * p;
  const size_t full = p / W, rest = p % W;
  const D pd = ones * static_cast<double>(p);
  const D valid_rest = iota < static_cast<double>(rest) ? ones : ones * 0.0;
  D p0r{}, p0i{};   // p at the first W samples of the period
  for (size_t b = 0; b < periods; ++b) {
    const size_t kb = k0 + b * p;
    if (b % kResync == 0) {
      InjectionPhasor<W>(w_ts, kb, &p0r, &p0i);
    } else {
      const D npr = p0r * period_c - p0i * period_s;
      p0i = p0r * period_s + p0i * period_c;
      p0r = npr;
    }
    D pr = p0r, pi = p0i;
    // Full vectors lie inside the period, hence inside the arrays.
    for (size_t v = 0; v < full; ++v) {
      const size_t k = kb + v * W;
      PaperStep<W, false, false>(a, in, k, m, W, MovingAverageWeight<W>(k, k0, k_end, pd), pr, pi,
                          ones);
      const D npr = pr * step_c - pi * step_s;
      pi = pr * step_s + pi * step_c;
      pr = npr;
    }
    if (rest > 0) {
      // The period's last, partial vector: lanes past the period are zeroed;
      // only at the end of the arrays are the loads themselves cut short.
      const size_t k = kb + full * W;
      const D weight = MovingAverageWeight<W>(k, k0, k_end, pd);
      if (k + W <= in.n) {
        PaperStep<W, false, true>(a, in, k, m, W, weight, pr, pi, valid_rest);
      } else {
        PaperStep<W, true, true>(a, in, k, m, in.n - k, weight, pr, pi, valid_rest);
      }
    }
    PutComplex<W>(&out->z0[2 * b], a.z0r, a.z0i);
    PutComplex<W>(&out->z1[2 * b], a.z1r, a.z1i);
    PutComplex<W>(&out->x01[2 * b], a.x01r, a.x01i);
    a.z0r = a.z0i = a.z1r = a.z1i = a.x01r = a.x01i = iota * 0.0;
  }
  PutComplex<W>(out->a0, a.a0r, a.a0i);
  PutComplex<W>(out->a1, a.a1r, a.a1i);
  PutComplex<W>(out->c01, a.c01r, a.c01i);
}

// ----------------------------------------------------------- residual

template <int W>
struct ResidualAcc {
  using D = typename Vec<W>::D;
  D b0r[2 * kResidualBins]{}, b0i[2 * kResidualBins]{}, b1r[2 * kResidualBins]{}, b1i[2 * kResidualBins]{};
  D s0r[4]{}, s0i[4]{}, s1r[4]{}, s1i[4]{};
  D hr[5]{}, hi[5]{};
};

// Bin q of index b (q = -kResidualBins..-1, 1..kResidualBins).
constexpr int BinOrder(int b) { return b < kResidualBins ? b - kResidualBins : b - kResidualBins + 1; }

template <int W, bool kMasked>
FLUXCAL_INLINE void ResidualStep(ResidualAcc<W>& a, typename Vec<W>::D ia, typename Vec<W>::D ib,
                                 typename Vec<W>::D ic, typename Vec<W>::D th, typename Vec<W>::D tau,
                                 typename Vec<W>::D pr, typename Vec<W>::D pi, const typename Vec<W>::D* twr,
                                 const typename Vec<W>::D* twi, const double* m, bool sidebands,
                                 typename Vec<W>::D valid) {
  using D = typename Vec<W>::D;
  const D yr = (2.0 * ia - ib - ic) * (1.0 / 3.0);
  const D yi = (ib - ic) * (1.0 / kSqrt3);
  D st, ct;
  SinCosV<W>(th, &st, &ct);
  const D c2 = ct * ct - st * st, s2 = 2.0 * ct * st;          // e^{j 2 theta}
  const D q1r = c2 * pr + s2 * pi, q1i = s2 * pr - c2 * pi;    // b1 = e^2 conj(p)
  const D fr = m[4] + m[6] * tau, fi = m[5] + m[7] * tau;      // c0 + c1 tau
  D rr = yr - (m[0] * pr - m[1] * pi) - (m[2] * q1r - m[3] * q1i) - (fr * ct - fi * st);
  D ri = yi - (m[0] * pi + m[1] * pr) - (m[2] * q1i + m[3] * q1r) - (fr * st + fi * ct);
  if constexpr (kMasked) {
    rr *= valid;
    ri *= valid;
  }
  const D r0r = rr * pr + ri * pi, r0i = ri * pr - rr * pi;        // r conj(p)
  const D r1r = rr * q1r + ri * q1i, r1i = ri * q1r - rr * q1i;    // r conj(b1)
  for (int b = 0; b < 2 * kResidualBins; ++b) {
    a.b0r[b] += r0r * twr[b] - r0i * twi[b];
    a.b0i[b] += r0r * twi[b] + r0i * twr[b];
    a.b1r[b] += r1r * twr[b] - r1i * twi[b];
    a.b1i[b] += r1r * twi[b] + r1i * twr[b];
  }
  if (sidebands) {
    // e^{-j 6 theta} = conj(e^2)^3, e^{-j 12 theta} its square.
    const D e4r = c2 * c2 - s2 * s2, e4i = -2.0 * c2 * s2;          // conj(e^2)^2
    const D e6r = e4r * c2 + e4i * s2, e6i = e4i * c2 - e4r * s2;    // conj(e^2)^3
    const D e12r = e6r * e6r - e6i * e6i, e12i = 2.0 * e6r * e6i;
    // m = -12, -6, 6, 12: e^{+j12}, e^{+j6}, e^{-j6}, e^{-j12}.
    const D orr[4] = {e12r, e6r, e6r, e12r}, oi[4] = {-e12i, -e6i, e6i, e12i};
    for (int j = 0; j < 4; ++j) {
      a.s0r[j] += r0r * orr[j] - r0i * oi[j];
      a.s0i[j] += r0r * oi[j] + r0i * orr[j];
      a.s1r[j] += r1r * orr[j] - r1i * oi[j];
      a.s1i[j] += r1r * oi[j] + r1i * orr[j];
    }
  }
  // r e^{-j h w t} = r0 e^{-j (h - 1) w t}: p^2, conj(p)^2, p^4, conj(p)^4, p^6.
  const D p2r = pr * pr - pi * pi, p2i = 2.0 * pr * pi;
  const D p4r = p2r * p2r - p2i * p2i, p4i = 2.0 * p2r * p2i;
  const D p6r = p4r * p2r - p4i * p2i, p6i = p4r * p2i + p4i * p2r;
  const D hr[5] = {p2r, p2r, p4r, p4r, p6r}, hi[5] = {p2i, -p2i, p4i, -p4i, p6i};
  for (int h = 0; h < 5; ++h) {
    a.hr[h] += r0r * hr[h] - r0i * hi[h];
    a.hi[h] += r0r * hi[h] + r0i * hr[h];
  }
}

template <int W>
FLUXCAL_INLINE ResidualSums ResidualKernel(const PhaseArrays& in, size_t n, double w_ts, double t_mid, double ts,
                                           const double* model, bool sidebands) {
  using D = typename Vec<W>::D;
  ResidualAcc<W> a;
  const D iota = Iota<W>(), ones = iota * 0.0 + 1.0;
  const double step_c = std::cos(w_ts * W), step_s = std::sin(w_ts * W);
  // Twiddles per bin and lane, advanced by W samples per vector and
  // evaluated afresh every kResync vectors, as the injection phasor.
  D twr[2 * kResidualBins], twi[2 * kResidualBins];
  double tstep_c[2 * kResidualBins], tstep_s[2 * kResidualBins], tw_rate[2 * kResidualBins];
  for (int b = 0; b < 2 * kResidualBins; ++b) {
    tw_rate[b] = -kTwoPi * BinOrder(b) / static_cast<double>(n);
    tstep_c[b] = std::cos(tw_rate[b] * W);
    tstep_s[b] = std::sin(tw_rate[b] * W);
  }
  auto twiddles_at = [&](size_t k) {
    for (int b = 0; b < 2 * kResidualBins; ++b) SinCosV<W>((iota + static_cast<double>(k)) * tw_rate[b], &twi[b], &twr[b]);
  };
  D pr{}, pi{};
  size_t k = 0, it = 0;
  for (; k + W <= n; k += W, ++it) {
    if (it % kResync == 0) {
      InjectionPhasor<W>(w_ts, k, &pr, &pi);
      twiddles_at(k);
    }
    const D tau = (iota + static_cast<double>(k)) * ts - t_mid;
    ResidualStep<W, false>(a, Load<W>(in.ia_a + k), Load<W>(in.ib_a + k), Load<W>(in.ic_a + k),
                           Load<W>(in.theta_e_rad + k), tau, pr, pi, twr, twi, model, sidebands, ones);
    const D npr = pr * step_c - pi * step_s;
    pi = pr * step_s + pi * step_c;
    pr = npr;
    for (int b = 0; b < 2 * kResidualBins; ++b) {
      const D nr = twr[b] * tstep_c[b] - twi[b] * tstep_s[b];
      twi[b] = twr[b] * tstep_s[b] + twi[b] * tstep_c[b];
      twr[b] = nr;
    }
  }
  if (k < n) {
    const size_t rest = n - k;
    InjectionPhasor<W>(w_ts, k, &pr, &pi);
    twiddles_at(k);
    const D tau = (iota + static_cast<double>(k)) * ts - t_mid;
    const D valid = iota < static_cast<double>(rest) ? ones : ones * 0.0;
    ResidualStep<W, true>(a, LoadPartial<W>(in.ia_a + k, rest), LoadPartial<W>(in.ib_a + k, rest),
                          LoadPartial<W>(in.ic_a + k, rest), LoadPartial<W>(in.theta_e_rad + k, rest), tau, pr, pi,
                          twr, twi, model, sidebands, valid);
  }
  ResidualSums out;
  for (int b = 0; b < 2 * kResidualBins; ++b) {
    PutComplex<W>(out.bins0[b], a.b0r[b], a.b0i[b]);
    PutComplex<W>(out.bins1[b], a.b1r[b], a.b1i[b]);
  }
  for (int j = 0; j < 4; ++j) {
    PutComplex<W>(out.side0[j], a.s0r[j], a.s0i[j]);
    PutComplex<W>(out.side1[j], a.s1r[j], a.s1i[j]);
  }
  for (int h = 0; h < 5; ++h) PutComplex<W>(out.harm[h], a.hr[h], a.hi[h]);
  return out;
}

// -------------------------------------------------------------- speed

template <int W>
FLUXCAL_INLINE double SlopeKernel(const double* th, size_t n) {
  using D = typename Vec<W>::D;
  if (n < 2) return 0.0;
  const double nn = static_cast<double>(n);
  D acc{};
  const D iota = Iota<W>();
  size_t j = 1;
  // wrap(d) = d - 2 pi round(d / 2 pi): the increment of the unwrapped angle.
  for (; j + W <= n; j += W) {
    D d = Load<W>(th + j) - Load<W>(th + j - 1);
    d -= kTwoPi * ((d * (1.0 / kTwoPi) + kRound) - kRound);
    const D jv = iota + static_cast<double>(j);
    acc += jv * (nn - jv) * d;
  }
  double sum = HorizontalSum<W>(acc);
  for (; j < n; ++j) {
    double d = th[j] - th[j - 1];
    d -= kTwoPi * ((d * (1.0 / kTwoPi) + kRound) - kRound);
    const double jd = static_cast<double>(j);
    sum += jd * (nn - jd) * d;
  }
  return 6.0 * sum / (nn * (nn * nn - 1.0));
}

template <int W>
FLUXCAL_INLINE void SinCosKernel(const double* x, size_t n, double* s, double* c) {
  using D = typename Vec<W>::D;
  for (size_t k = 0; k < n; k += W) {
    const size_t count = n - k < static_cast<size_t>(W) ? n - k : W;
    D sv, cv;
    SinCosV<W>(LoadPartial<W>(x + k, count), &sv, &cv);
    for (size_t i = 0; i < count; ++i) {
      s[k + i] = sv[i];
      c[k + i] = cv[i];
    }
  }
}

// ------------------------------------------------------- instantiations
// Lanes per vector: 2 fills an SSE2 (or NEON) register; AVX2 has 16 ymm
// registers, so 4 lanes; AVX-512 has 32 registers of 8 lanes.

struct Variant {
  LsqSums (*lsq)(const PhaseArrays&, size_t, double, double, double);
  ResidualSums (*residual)(const PhaseArrays&, size_t, double, double, double, const double*, bool);
  void (*paper)(const PhaseArrays&, size_t, size_t, size_t, size_t, double, PaperSums*);
  double (*slope)(const double*, size_t);
  void (*sincos)(const double*, size_t, double*, double*);
};

// Every kernel with `lanes` lanes, compiled for one target (the attribute
// must sit on the function the kernels are inlined into).
#define FLUXCAL_DEFINE_VARIANT(name, target, lanes)                                          \
  target LsqSums name##Lsq(const PhaseArrays& in, size_t n, double w_ts, double t_mid,     \
                           double ts) {                                                     \
    return LsqKernel<lanes>(in, n, w_ts, t_mid, ts);                                        \
  }                                                                                         \
  target ResidualSums name##Residual(const PhaseArrays& in, size_t n, double w_ts, double t_mid, \
                                     double ts, const double* model, bool sidebands) {       \
    return ResidualKernel<lanes>(in, n, w_ts, t_mid, ts, model, sidebands);                 \
  }                                                                                         \
  target void name##Paper(const PhaseArrays& in, size_t m, size_t p, size_t k0,             \
                          size_t periods, double w_ts, PaperSums* out) {                    \
    PaperKernel<lanes>(in, m, p, k0, periods, w_ts, out);                                   \
  }                                                                                         \
  target double name##Slope(const double* th, size_t n) { return SlopeKernel<lanes>(th, n); } \
  target void name##SinCos(const double* x, size_t n, double* s, double* c) {               \
    SinCosKernel<lanes>(x, n, s, c);                                                        \
  }                                                                                         \
  constexpr Variant k##name{&name##Lsq, &name##Residual, &name##Paper, &name##Slope, &name##SinCos};

FLUXCAL_DEFINE_VARIANT(Baseline, , 2)
#ifdef FLUXCAL_X86_DISPATCH
FLUXCAL_DEFINE_VARIANT(Avx2, FLUXCAL_TARGET_AVX2, 4)
FLUXCAL_DEFINE_VARIANT(Avx512, FLUXCAL_TARGET_AVX512, 8)
#endif
#undef FLUXCAL_DEFINE_VARIANT

// An unsupported request runs the baseline (callers check IsaSupported).
const Variant& Select(Isa isa) {
  switch (IsaSupported(isa) ? isa : Isa::kBaseline) {
#ifdef FLUXCAL_X86_DISPATCH
    case Isa::kAvx512: return kAvx512;
    case Isa::kAvx2: return kAvx2;
#endif
    default: return kBaseline;
  }
}

}  // namespace

bool IsaSupported(Isa isa) {
  switch (isa) {
    case Isa::kBaseline:
      return true;
#ifdef FLUXCAL_X86_DISPATCH
    case Isa::kAvx2:
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
    case Isa::kAvx512:
      return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma") &&
             __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
             __builtin_cpu_supports("avx512dq");
#else
    default:
      return false;
#endif
  }
  return false;
}

Isa BestIsa() {
  static const Isa best = IsaSupported(Isa::kAvx512) ? Isa::kAvx512
                          : IsaSupported(Isa::kAvx2) ? Isa::kAvx2
                                                     : Isa::kBaseline;
  return best;
}

const char* IsaName(Isa isa) {
  switch (isa) {
    case Isa::kBaseline: return "baseline";
    case Isa::kAvx2: return "avx2";
    case Isa::kAvx512: return "avx512";
  }
  return "unknown";
}

LsqSums LsqNormalSums(const PhaseArrays& in, size_t n_used, double w_ts_rad, double t_mid_s,
                      double ts_s, Isa isa) {
  return Select(isa).lsq(in, n_used, w_ts_rad, t_mid_s, ts_s);
}

ResidualSums ResidualSumsOf(const PhaseArrays& in, size_t n_used, double w_ts_rad, double t_mid_s, double ts_s,
                            const double model[8], bool sidebands, Isa isa) {
  return Select(isa).residual(in, n_used, w_ts_rad, t_mid_s, ts_s, model, sidebands);
}

PaperSums PaperFilterSums(const PhaseArrays& in, size_t m, size_t p, size_t k0, size_t periods,
                          double w_ts_rad, Isa isa) {
  PaperSums out;
  Select(isa).paper(in, m, p, k0, periods, w_ts_rad, &out);
  return out;
}

double AngleSlopeRadPerSample(const double* theta_e_rad, size_t n, Isa isa) {
  return Select(isa).slope(theta_e_rad, n);
}

void SinCos(const double* x, size_t n, double* s, double* c, Isa isa) {
  Select(isa).sincos(x, n, s, c);
}

}  // namespace fluxcal::ident::kernels
