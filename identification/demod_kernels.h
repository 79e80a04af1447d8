// Vectorised inner loops of the HF demodulators (internal to
// identification/; demod.cc turns their sums into phasors).
//
// Why a separate file: the demodulators' cost is one sine/cosine of the
// measured angle per sample plus a few dozen multiply-adds. Written with GCC
// vector extensions and compiled once per instruction set (baseline x86-64 /
// any CPU, AVX2+FMA, AVX-512), picked at run time from what the CPU reports,
// they reach several times the throughput of the scalar loops without a
// `-march` flag in the build (docs/performance.md). Every variant evaluates
// the same sums; they differ only in rounding (tests/identification
// kernels_test.cc compares them).
#ifndef FLUXCAL_IDENTIFICATION_DEMOD_KERNELS_H_
#define FLUXCAL_IDENTIFICATION_DEMOD_KERNELS_H_

#include <cstddef>
#include <vector>

namespace fluxcal::ident::kernels {

enum class Isa { kBaseline, kAvx2, kAvx512 };

// The widest variant this CPU runs (kBaseline off x86-64).
Isa BestIsa();
bool IsaSupported(Isa isa);
const char* IsaName(Isa isa);

// Sums of the least-squares demodulator's normal equations over samples
// k = 0..n-1 (docs/identification.md, eq. (D1)); with p_k = e^{j w Ts k},
// e_k = e^{j theta_k}, y_k the Clarke current and tau_k = k Ts - t_mid:
//   g01 = sum e_k^2 conj(p_k)^2        (= conj(b0) b1)
//   g02 = sum e_k conj(p_k)            (= conj(b0) b2; conj(b1) b2 = conj(g02))
//   g03 = sum tau_k e_k conj(p_k)
//   h0 = sum conj(p_k) y_k, h1 = sum conj(e_k)^2 p_k y_k,
//   h2 = sum conj(e_k) y_k, h3 = sum tau_k conj(e_k) y_k, yy = sum |y_k|^2.
// Complex sums as [re, im].
struct LsqSums {
  double g01[2] = {0, 0}, g02[2] = {0, 0}, g03[2] = {0, 0};
  double h0[2] = {0, 0}, h1[2] = {0, 0}, h2[2] = {0, 0}, h3[2] = {0, 0};
  double yy = 0;
};

struct PhaseArrays {
  const double* ia_a;
  const double* ib_a;
  const double* ic_a;
  const double* theta_e_rad;
  size_t n;                      // valid samples in each array
};

// w_ts_rad = w_i Ts, the injection phase advance per sample.
LsqSums LsqNormalSums(const PhaseArrays& in, size_t n_used, double w_ts_rad, double t_mid_s,
                      double ts_s, Isa isa);

// The paper's cascade evaluated as weighted sums (demod.cc, PaperDemodulate):
// over k in [k0, k0 + periods P), with y_k the Clarke transform of
// x_k - 2 x_{k-M} + x_{k-2M}, p_k = e^{j w Ts k}, b1_k = e_k^2 conj(p_k):
//   z0 = y conj(p), z1 = y conj(b1), x01 = p conj(b1),
// weighted by v_k = min(k - k0 + 1, P, k0 + periods P - k) (the number of
// one-period moving-average windows that hold sample k), and per period b
// unweighted (for the batch-means standard error).
struct PaperSums {
  double a0[2] = {0, 0}, a1[2] = {0, 0}, c01[2] = {0, 0};   // sum v z0, v z1, v x01
  std::vector<double> z0, z1, x01;   // per period b: re at 2b, im at 2b + 1
};
PaperSums PaperFilterSums(const PhaseArrays& in, size_t m, size_t p, size_t k0, size_t periods,
                          double w_ts_rad, Isa isa);

// The LSQ residual's sums (demod.cc, ResidualAnalysis, which derives what
// they are for): with the fitted model's residual
//   r_k = y_k - I0 p_k - I1 b1_k - (c0 + c1 tau_k) e_k,   b1 = e^2 conj(p),
// r0 = r conj(p), r1 = r conj(b1) and the Fourier twiddles
// t_qk = e^{-j 2 pi q k / n} for q = -kResidualBins..-1, 1..kResidualBins:
//   bins0[b] = sum r0_k t_qk, bins1[b] = sum r1_k t_qk  (b in q's order);
//   side0[j], side1[j] = sum r0 (resp. r1) e^{-j m theta_k} for
//     m = -12, -6, 6, 12 (only when `sidebands`);
//   harm[h] = sum r0 conj(p)^(h' - 1) for the injection orders
//     h' = -1, 3, -3, 5, -5.
// `model` = {Re I0, Im I0, Re I1, Im I1, Re c0, Im c0, Re c1, Im c1}.
inline constexpr int kResidualBins = 10;
struct ResidualSums {
  double bins0[2 * kResidualBins][2] = {}, bins1[2 * kResidualBins][2] = {};
  double side0[4][2] = {}, side1[4][2] = {};
  double harm[5][2] = {};
};
ResidualSums ResidualSumsOf(const PhaseArrays& in, size_t n_used, double w_ts_rad, double t_mid_s, double ts_s,
                            const double model[8], bool sidebands, Isa isa);

// 6 / (n (n^2 - 1)) sum_{j=1}^{n-1} j (n - j) wrap(theta_j - theta_{j-1}):
// the least-squares slope (rad per sample) of the unwrapped angle against the
// sample index, written as a weighted sum of increments so it vectorises
// (docs/identification.md, Sec. "Speed").
double AngleSlopeRadPerSample(const double* theta_e_rad, size_t n, Isa isa);

// sin and cos of x[i] by the kernels' polynomial (for tests).
void SinCos(const double* x, size_t n, double* s, double* c, Isa isa);

}  // namespace fluxcal::ident::kernels

#endif  // FLUXCAL_IDENTIFICATION_DEMOD_KERNELS_H_
