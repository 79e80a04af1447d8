// Flux-linkage model families for the fits, templated on the scalar so that
// Ceres differentiates the same equations the calibration evaluates.
//
// Every family is the gradient of a co-energy W'(id, iq), so the
// differential inductance (the Hessian) is symmetric by construction, has
// psi_d(0, 0) = psi_pm, and all but smooth-asym respect the machine's
// symmetry (psi_d even, psi_q odd in iq, so psi_q(id, 0) = 0).
//
//  kAnalytic: the twin's saturation model (simulation/saturation_model.h,
//    eq. (M1)), 7 parameters with the cross-saturation current scale ix_a
//    held fixed: psi_pm, Ld0, Lq0, Id_sat, Iq_sat, g_cross (, ix).
//  kPoly<N>: W' = psi_pm id + L0 I0^2 sum c_ab x^a y^b, x = id/I0, y = iq/I0,
//    over 2 <= a + b <= N with b even (so psi_q(id, 0) = 0 and no term
//    linear in id alone, so psi_d(0, 0) = psi_pm). L0 = 1e-4 H, I0 = 100 A
//    scale the coefficients to order one. Flexible: any smooth conservative
//    map is approximated as N grows; N is chosen by BIC.
//  kSpline<R>: W' = psi_pm id + L0 I0^2 (S(id, iq) - S_d(0, 0) id),
//    S a tensor-product quartic B-spline with R uniform spans over the id
//    range and 2R over [-Q, Q] in iq, its iq basis folded to even functions
//    (B_j + B_{N-1-j}) so psi_q(id, 0) = 0; the linear term removes S's
//    slope at the origin so psi_d(0, 0) = psi_pm. Quartic: W' is C3, the
//    inductance C1. Local, so one region's data do not bend another's. Beyond
//    the knot range each 1-D basis function continues as its second-order
//    Taylor polynomial at the edge: the co-energy stays C2 and a gradient
//    field (inductance symmetric) everywhere, the inductance continues
//    smoothly instead of oscillating. R is chosen by BIC.
//  smooth / smooth-asym: the same quartic co-energy spline with ~8 spans per
//    axis over the data box and a roughness penalty on all third derivatives
//    of W (surface.cc, SmoothingPenalty); "smooth" is even in iq (the measured
//    |iq| range mirrored; older calibrations: the iq basis folded like
//    spline<R>), "smooth-asym" lets psi_q(id, 0) differ from zero away from
//    id = 0 (psi_q(0, 0) = 0: d is the magnet axis).
#ifndef FLUXCAL_FITTING_FLUX_FAMILY_H_
#define FLUXCAL_FITTING_FLUX_FAMILY_H_

#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "simulation/saturation_model.h"

namespace fluxcal::fit {

inline constexpr double kPolyL0H = 1e-4;
inline constexpr double kPolyI0A = 100.0;

// Exponents (a, b) of the polynomial family of total degree <= n.
inline std::vector<std::pair<int, int>> PolyTerms(int n) {
  std::vector<std::pair<int, int>> t;
  for (int deg = 2; deg <= n; ++deg)
    for (int b = 0; b <= deg; b += 2) t.push_back({deg - b, b});
  return t;
}

template <typename T>
T IntPow(const T& x, int n) {
  T r(1.0);
  for (int k = 0; k < n; ++k) r = r * x;
  return r;
}

// The largest degree a polynomial family has (the decoders refuse more:
// fitting/calibration.cc, pipeline/calibration_codec.cc).
inline constexpr int kPolyMaxDegree = 12;

// x^0..x^n by repeated multiplication, as IntPow computes each (the same
// products in the same order: bit-identical), into `pw` (n <= kPolyMaxDegree).
template <typename T>
void PolyPowers(const T& x, int n, T* pw) {
  pw[0] = T(1.0);
  for (int k = 1; k <= n; ++k) pw[k] = pw[k - 1] * x;
}

// Polynomial family. p[0] = psi_pm, p[1..] = c_ab in PolyTerms(n) order
// (deg = 2..n, b = 0, 2, .., deg, a = deg - b), walked here without
// building the list: these run at every sub-step of a replay (measured:
// the list's allocation and the repeated powers were two thirds of a
// diagnosis on a polynomial calibration).
template <typename T, typename P>
void PolyFlux(int n, const T& id, const T& iq, const P* p, T* psi_d, T* psi_q) {
  // A degree the powers' buffer cannot hold (the decoders and the fit's
  // model names never make one): no value, not a write past the buffer.
  if (n < 0 || n > kPolyMaxDegree) {
    *psi_d = *psi_q = T(std::numeric_limits<double>::quiet_NaN());
    return;
  }
  T xp[kPolyMaxDegree + 1], yp[kPolyMaxDegree + 1];
  PolyPowers(T(id / kPolyI0A), n, xp);
  PolyPowers(T(iq / kPolyI0A), n, yp);
  T sd(0.0), sq(0.0);
  int k = 1;
  for (int deg = 2; deg <= n; ++deg) {
    for (int b = 0; b <= deg; b += 2, ++k) {
      const int a = deg - b;
      if (a > 0) sd = sd + p[k] * double(a) * xp[a - 1] * yp[b];
      if (b > 0) sq = sq + p[k] * double(b) * xp[a] * yp[b - 1];
    }
  }
  *psi_d = p[0] + kPolyL0H * kPolyI0A * sd;
  *psi_q = kPolyL0H * kPolyI0A * sq;
}

template <typename T, typename P>
void PolyInductance(int n, const T& id, const T& iq, const P* p, T* ldd, T* lqq, T* ldq) {
  // A degree the powers' buffer cannot hold (the decoders and the fit's
  // model names never make one): no value, not a write past the buffer.
  if (n < 0 || n > kPolyMaxDegree) {
    *ldd = *lqq = *ldq = T(std::numeric_limits<double>::quiet_NaN());
    return;
  }
  T xp[kPolyMaxDegree + 1], yp[kPolyMaxDegree + 1];
  PolyPowers(T(id / kPolyI0A), n, xp);
  PolyPowers(T(iq / kPolyI0A), n, yp);
  T dd(0.0), qq(0.0), dq(0.0);
  int k = 1;
  for (int deg = 2; deg <= n; ++deg) {
    for (int b = 0; b <= deg; b += 2, ++k) {
      const int a = deg - b;
      if (a > 1) dd = dd + p[k] * double(a * (a - 1)) * xp[a - 2] * yp[b];
      if (b > 1) qq = qq + p[k] * double(b * (b - 1)) * xp[a] * yp[b - 2];
      if (a > 0 && b > 0) dq = dq + p[k] * double(a * b) * xp[a - 1] * yp[b - 1];
    }
  }
  *ldd = kPolyL0H * dd;
  *lqq = kPolyL0H * qq;
  *ldq = kPolyL0H * dq;
}

// ---- Quartic B-spline co-energy --------------------------------------

inline constexpr int kSplineDegree = 4;

// The knot layout of a spline family. Legacy spline<R>: `spans` uniform
// spans over [id_lo_a, id_hi_a] and 2R over [-iq_hi_a, iq_hi_a], folded to
// even functions of iq. Smoothing splines (`smoothing`, name "smooth"):
// `spans` over id and `spans_q` over [iq_lo_a, iq_hi_a]; `symmetric`
// makes the co-energy even in iq (psi_d even, psi_q odd: the machine's
// symmetry), otherwise psi_q(id, 0) is free ("smooth-asym"), a hypothesis
// the fit weighs by cross-validation only where the data measured both
// halves of the iq axis (select.cc).
// A symmetric smoothing spline has one of two layouts:
//  - folded (calibrations written before `mirrored` existed): the iq basis
//    over [-iq_hi_a, iq_hi_a] (iq_lo_a = -iq_hi_a, even spans_q) folded to
//    even functions, like spline<R>;
//  - `mirrored`: the basis over the measured |iq| range [iq_lo_a, iq_hi_a]
//    (iq_lo_a a margin below 0), evaluated at |iq|, its coefficients
//    constrained so that S_q(id, 0) = 0 (MirrorConstraint): the whole knot
//    grid on the half the data measured, where the folded layout spent half
//    of it on the mirror image (docs/fitting.md says what that cost).
struct SplineDomain {
  int spans = 0;
  double id_lo_a = -100, id_hi_a = 0, iq_hi_a = 100;
  bool smoothing = false;
  int spans_q = 0;            // smoothing only
  double iq_lo_a = -100;      // smoothing only
  bool symmetric = true;
  bool mirrored = false;      // smoothing && symmetric only
  int SpansQ() const { return smoothing ? spans_q : 2 * spans; }
  double IqLo() const { return smoothing ? iq_lo_a : -iq_hi_a; }
  bool Folded() const { return !smoothing || (symmetric && !mirrored); }
  int NumD() const { return spans + kSplineDegree; }            // id basis
  int NumQ() const { return SpansQ() + kSplineDegree; }         // iq basis
  // iq coefficients: folded pairs share one; the mirrored layout gives up
  // one to its constraint.
  int NumEven() const { return Folded() ? NumQ() / 2 : (mirrored ? NumQ() - 1 : NumQ()); }
  int NumCoefficients() const { return NumD() * NumEven(); }
  // Coefficient index of iq basis j (folded: B_j and B_{NumQ-1-j} share
  // one). Not for the mirrored layout: MirrorConstraint::Terms.
  int QIndex(int j) const { return Folded() && j >= NumEven() ? NumQ() - 1 - j : j; }
};

// Values and first two derivatives of the kSplineDegree + 1 uniform B-spline
// basis functions that are nonzero at x, on `spans` spans over [lo, hi]
// (basis i supported on knots lo + (i - p) h .. lo + (i + 1) h). Beyond
// [lo, hi] each function continues as its second-order Taylor polynomial at
// the edge. The Cox-de Boor triangle on uniform knots (Piegl & Tiller, The
// NURBS Book, A2.2) with derivatives from lower degrees: for uniform knots
// d/dx N_{i,p} = (N_{i,p-1} - N_{i+1,p-1}) / h.
struct Basis1d {
  int first = 0;                       // index of v[0]
  double v[kSplineDegree + 1], d1[kSplineDegree + 1], d2[kSplineDegree + 1];
};
inline Basis1d EvalBasis(double x, double lo, double hi, int spans) {
  constexpr int p = kSplineDegree;
  const double h = (hi - lo) / spans;
  double s = (x - lo) / h, delta = 0;   // delta: distance beyond the edge [in h]
  if (s < 0) { delta = s; s = 0; }
  if (s > spans) { delta = s - spans; s = spans; }
  int m = static_cast<int>(std::floor(s));
  if (m >= spans) m = spans - 1;
  const double u = s - m;               // in [0, 1]
  // N[k][r]: degree-k functions nonzero in span m, r = 0..k (function
  // index m + (p - k) + r in the degree-p numbering).
  double N[p + 1][p + 1] = {};
  N[0][0] = 1.0;
  for (int k = 1; k <= p; ++k) {
    // Knots at the integers, N[k][r] = N_{j,k} with j = m - k + r:
    //   N_{j,k}(s) = ((s - j) N_{j,k-1}(s) + (j + k + 1 - s) N_{j+1,k-1}(s)) / k,
    // s - j = u + k - r, j + k + 1 - s = r + 1 - u; N_{j,k-1} is
    // N[k-1][r-1] and N_{j+1,k-1} is N[k-1][r].
    for (int r = 0; r <= k; ++r) {
      const double lower = r > 0 ? N[k - 1][r - 1] : 0.0;
      const double upper = r < k ? N[k - 1][r] : 0.0;
      N[k][r] = ((u + k - r) * lower + (r + 1 - u) * upper) / k;
    }
  }
  Basis1d b;
  b.first = m;
  for (int r = 0; r <= p; ++r) {
    // d/ds N_{j,p} = N_{j,p-1} - N_{j+1,p-1} (unit knot spacing), i.e.
    // N[p-1][r-1] - N[p-1][r]; d2/ds2 = N[p-2][r-2] - 2 N[p-2][r-1] + N[p-2][r].
    const double a1 = r > 0 ? N[p - 1][r - 1] : 0.0, b1 = r < p ? N[p - 1][r] : 0.0;
    const double a2 = r > 1 ? N[p - 2][r - 2] : 0.0, b2 = (r >= 1 && r <= p - 1) ? N[p - 2][r - 1] : 0.0,
                 c2 = r < p - 1 ? N[p - 2][r] : 0.0;
    b.v[r] = N[p][r];
    b.d1[r] = (a1 - b1) / h;
    b.d2[r] = (a2 - 2.0 * b2 + c2) / (h * h);
    if (delta != 0.0) {
      const double dx = delta * h;
      b.v[r] += b.d1[r] * dx + 0.5 * b.d2[r] * dx * dx;
      b.d1[r] += b.d2[r] * dx;
    }
  }
  return b;
}

// The mirrored layout's constraint S_q(id, 0) = 0 for every id: for each id
// basis function i, sum_j c_ij B_j'(0) = 0. One iq coefficient per id row,
// the pivot (the basis function with the steepest slope at 0), is then the
// combination c_i,pivot = sum_{j != pivot} w_j c_ij, w_j = -B_j'(0) /
// B_pivot'(0); the others are the parameters, in order, the pivot left out.
struct MirrorConstraint {
  Basis1d b0;                          // iq basis at 0
  int pivot = 0;
  double w[kSplineDegree + 1] = {};    // w[c] for iq basis b0.first + c (0 at the pivot)
  int ne = 0;
  explicit MirrorConstraint(const SplineDomain& dom)
      : b0(EvalBasis(0.0, dom.IqLo(), dom.iq_hi_a, dom.SpansQ())), ne(dom.NumEven()) {
    int best = 0;
    for (int c = 1; c <= kSplineDegree; ++c) {
      if (std::abs(b0.d1[c]) > std::abs(b0.d1[best])) best = c;
    }
    pivot = b0.first + best;
    for (int c = 0; c <= kSplineDegree; ++c) w[c] = c == best ? 0.0 : -b0.d1[c] / b0.d1[best];
  }
  // Parameter index of free iq coefficient j (j != pivot).
  int Reduced(int j) const { return j < pivot ? j : j - 1; }
  // (parameter offset within an id row, weight) of full iq coefficient j.
  template <typename F>
  void Terms(int j, F add) const {
    if (j != pivot) {
      add(Reduced(j), 1.0);
      return;
    }
    for (int c = 0; c <= kSplineDegree; ++c) {
      if (w[c] != 0.0) add(Reduced(b0.first + c), w[c]);
    }
  }
  // The full coefficient c_ij from the parameters p (p[0] = psi_pm).
  template <typename T, typename P>
  T Coefficient(const P* p, int i, int j) const {
    T r(0.0);
    Terms(j, [&](int e, double wt) { r += p[1 + i * ne + e] * wt; });
    return r;
  }
};

// psi (when psi_d is given) and L (when ldd is given) of the spline family.
// p[0] = psi_pm, p[1 + i * NumEven() + e] = coefficient of B_i(id) E_e(iq),
// E_e = B_e + B_{NumQ()-1-e}. Only flux needs S's slope at the origin.
// The mirrored layout: with q = |iq|, s = sign(iq) and S the spline over
// the measured |iq| range, W'(id, iq) = psi_pm id + L0 I0^2 (S(id, q) -
// S_d(0, 0) id): even in iq by construction, and, S_q(id, 0) being 0
// (MirrorConstraint), C2 across iq = 0 (flux and inductance continuous;
// Lqq's slope may turn there, as a rib saturating from zero current does):
//   psi_d = psi_pm + kW (S_d(id, q) - S_d(0, 0)),  psi_q = s kW S_q(id, q),
//   Ldd = kW S_dd(id, q),  Lqq = kW S_qq(id, q),  Ldq = s kW S_dq(id, q).
template <typename T, typename P>
void SplineFluxAndInductance(const SplineDomain& dom, double id, double iq, const P* p, T* psi_d,
                             T* psi_q, T* ldd, T* lqq, T* ldq) {
  if (!std::isfinite(id) || !std::isfinite(iq)) {
    // A diverging simulation's state: no basis to index; NaN out.
    const T nan(std::numeric_limits<double>::quiet_NaN());
    for (T* out : {psi_d, psi_q, ldd, lqq, ldq}) {
      if (out != nullptr) *out = nan;
    }
    return;
  }
  // The two layouts differ only in how a coefficient c_ij is read from p
  // (the mirrored one's pivot is a weighted sum, MirrorConstraint; the
  // folded one's an index fold) and in the iq argument (|iq| and its sign
  // for the mirrored one); the sums below are the same for both.
  const bool mirrored = dom.mirrored && dom.smoothing && dom.symmetric;
  const double s = mirrored && iq < 0 ? -1.0 : 1.0, q = mirrored ? std::abs(iq) : iq;
  const Basis1d bd = EvalBasis(id, dom.id_lo_a, dom.id_hi_a, dom.spans);
  const Basis1d bq = EvalBasis(q, dom.IqLo(), dom.iq_hi_a, dom.SpansQ());
  // Coefficients scaled like the polynomial family's: W' in L0 I0^2 units.
  const double kW = kPolyL0H * kPolyI0A * kPolyI0A;
  // b0q_of(): the iq basis at 0 (only flux needs it).
  auto evaluate = [&](auto coefficient, auto b0q_of) {
    // sum over the nonzero basis products of coefficient * f(a, c).
    auto sum = [&](const Basis1d& bdd, const Basis1d& bqq, auto f) {
      T r(0.0);
      for (int a = 0; a <= kSplineDegree; ++a)
        for (int c = 0; c <= kSplineDegree; ++c) r += coefficient(bdd.first + a, bqq.first + c) * f(a, c);
      return r;
    };
    if (psi_d != nullptr) {
      const Basis1d b0d = EvalBasis(0.0, dom.id_lo_a, dom.id_hi_a, dom.spans);
      const Basis1d b0q = b0q_of();
      const T slope0 = sum(b0d, b0q, [&](int a, int c) { return b0d.d1[a] * b0q.v[c]; });
      *psi_d = p[0] + kW * (sum(bd, bq, [&](int a, int c) { return bd.d1[a] * bq.v[c]; }) - slope0);
      *psi_q = s * kW * sum(bd, bq, [&](int a, int c) { return bd.v[a] * bq.d1[c]; });
      if (!mirrored && !dom.Folded()) {
        // psi_q(0, 0) = 0 also without the fold: d is the magnet axis
        // (recording-format.md), so zero current links no q flux; psi_q(id, 0)
        // away from id = 0 stays free.
        *psi_q = *psi_q - kW * sum(b0d, b0q, [&](int a, int c) { return b0d.v[a] * b0q.d1[c]; });
      }
    }
    if (ldd != nullptr) {
      *ldd = kW * sum(bd, bq, [&](int a, int c) { return bd.d2[a] * bq.v[c]; });
      *lqq = kW * sum(bd, bq, [&](int a, int c) { return bd.v[a] * bq.d2[c]; });
      *ldq = s * kW * sum(bd, bq, [&](int a, int c) { return bd.d1[a] * bq.d1[c]; });
    }
  };
  if (mirrored) {
    const MirrorConstraint mc(dom);
    evaluate([&](int i, int j) { return mc.Coefficient<T>(p, i, j); }, [&] { return mc.b0; });
  } else {
    const int ne = dom.NumEven();
    evaluate([&](int i, int j) { return p[1 + i * ne + dom.QIndex(j)]; },
             [&] { return EvalBasis(0.0, dom.IqLo(), dom.iq_hi_a, dom.SpansQ()); });
  }
}

// A spline family's surfaces at fixed parameters, for evaluating a fitted
// calibration many times (the tables' solvers call it ~10^5 times per
// table). SplineFluxAndInductance re-derives per call what does not depend
// on the operating point: the full coefficient grid (the mirrored layout's
// pivot coefficient is a weighted sum of five parameters, the folded one's
// an index fold), the basis at the origin and S's slope there. Here they
// are computed once, and one call gives flux and inductance from one pair
// of 1-D bases. Each coefficient and each sum is formed with the same
// operations in the same order as SplineFluxAndInductance<double>, so the
// values are the same to the last bit (tests/fitting/spline_test.cc).
class SplineSurface {
 public:
  SplineSurface() = default;
  SplineSurface(const SplineDomain& dom, const double* p) : dom_(dom), nq_(dom.NumQ()), psi_pm_(p[0]) {
    const int nd = dom.NumD();
    coef_.resize(static_cast<size_t>(nd) * nq_);
    const bool mirrored = dom.mirrored && dom.smoothing && dom.symmetric;
    const MirrorConstraint mc(dom);
    for (int i = 0; i < nd; ++i) {
      for (int j = 0; j < nq_; ++j) {
        double c;
        if (mirrored) {
          c = mc.Coefficient<double>(p, i, j);
        } else {
          c = p[1 + i * dom.NumEven() + dom.QIndex(j)];
        }
        coef_[static_cast<size_t>(i) * nq_ + j] = c;
      }
    }
    mirrored_ = mirrored;
    const Basis1d b0d = EvalBasis(0.0, dom.id_lo_a, dom.id_hi_a, dom.spans);
    const Basis1d b0q = mirrored ? mc.b0 : EvalBasis(0.0, dom.IqLo(), dom.iq_hi_a, dom.SpansQ());
    double slope0 = 0.0, q0 = 0.0;
    for (int a = 0; a <= kSplineDegree; ++a) {
      for (int c = 0; c <= kSplineDegree; ++c) {
        const double k = Coef(b0d.first + a, b0q.first + c);
        slope0 += k * (b0d.d1[a] * b0q.v[c]);
        q0 += k * (b0d.v[a] * b0q.d1[c]);
      }
    }
    slope0_ = slope0;
    psi_q0_ = !mirrored && !dom.Folded() ? q0 : 0.0;
    subtract_q0_ = !mirrored && !dom.Folded();
  }
  bool empty() const { return coef_.empty(); }

  // Any of the outputs may be null (flux: psi_d and psi_q together,
  // inductance: the three together).
  void Eval(double id, double iq, double* psi_d, double* psi_q, double* ldd, double* lqq, double* ldq) const {
    if (!std::isfinite(id) || !std::isfinite(iq)) {
      // A diverging simulation's state: no basis to index; NaN out.
      for (double* out : {psi_d, psi_q, ldd, lqq, ldq}) {
        if (out != nullptr) *out = std::numeric_limits<double>::quiet_NaN();
      }
      return;
    }
    double s = 1.0, q = iq;
    if (mirrored_) {
      s = iq < 0 ? -1.0 : 1.0;
      q = std::abs(iq);
    }
    // The solvers step along iq at fixed id (Newton on a column or a
    // locus), so the id basis repeats from call to call: it is kept, per
    // thread, keyed on everything it depends on (x and the knots), so it is
    // never stale and a calibration stays safe to share between threads.
    thread_local struct {
      double x = std::numeric_limits<double>::quiet_NaN(), lo = 0, hi = 0;
      int spans = 0;
      Basis1d b;
    } last_d;
    if (!(id == last_d.x && dom_.id_lo_a == last_d.lo && dom_.id_hi_a == last_d.hi && dom_.spans == last_d.spans)) {
      last_d.b = EvalBasis(id, dom_.id_lo_a, dom_.id_hi_a, dom_.spans);
      last_d.x = id;
      last_d.lo = dom_.id_lo_a;
      last_d.hi = dom_.id_hi_a;
      last_d.spans = dom_.spans;
    }
    const Basis1d& bd = last_d.b;
    const Basis1d bq = EvalBasis(q, dom_.IqLo(), dom_.iq_hi_a, dom_.SpansQ());
    double sd = 0, sq = 0, sdd = 0, sqq = 0, sdq = 0;
    for (int a = 0; a <= kSplineDegree; ++a) {
      const double* row = &coef_[static_cast<size_t>(bd.first + a) * nq_ + bq.first];
      for (int c = 0; c <= kSplineDegree; ++c) {
        const double k = row[c];
        sd += k * (bd.d1[a] * bq.v[c]);
        sq += k * (bd.v[a] * bq.d1[c]);
        sdd += k * (bd.d2[a] * bq.v[c]);
        sqq += k * (bd.v[a] * bq.d2[c]);
        sdq += k * (bd.d1[a] * bq.d1[c]);
      }
    }
    const double kW = kPolyL0H * kPolyI0A * kPolyI0A;
    if (psi_d != nullptr) {
      *psi_d = psi_pm_ + kW * (sd - slope0_);
      *psi_q = mirrored_ ? s * kW * sq : kW * sq;
      if (subtract_q0_) *psi_q = *psi_q - kW * psi_q0_;
    }
    if (ldd != nullptr) {
      *ldd = kW * sdd;
      *lqq = kW * sqq;
      *ldq = mirrored_ ? s * kW * sdq : kW * sdq;
    }
  }

 private:
  double Coef(int i, int j) const { return coef_[static_cast<size_t>(i) * nq_ + j]; }
  SplineDomain dom_;
  int nq_ = 0;
  double psi_pm_ = 0, slope0_ = 0, psi_q0_ = 0;
  bool mirrored_ = false, subtract_q0_ = false;
  std::vector<double> coef_;   // full iq basis, row-major over the id basis
};

// The scalar value of a double or a ceres::Jet (its .a member): the spline's
// basis depends on the operating point, which is data, never a parameter.
inline double ScalarOf(double x) { return x; }
template <typename J>
double ScalarOf(const J& j) { return j.a; }

// A family instance: "analytic", "poly<N>" or "spline<R>".
struct Family {
  enum Kind { kAnalytic, kPoly, kSpline } kind = kAnalytic;
  int degree = 0;          // kPoly only
  SplineDomain spline;     // kSpline only
  int NumParams() const {
    if (kind == kAnalytic) return sim::kSaturationParams;
    if (kind == kPoly) return 1 + static_cast<int>(PolyTerms(degree).size());
    return 1 + spline.NumCoefficients();
  }
  // psi_d even and psi_q odd in iq for every parameter value: the analytic
  // family (eq. (M1) is even in iq for psi_d, odd for psi_q), the
  // polynomials (b even) and the folded splines. smooth-asym is not.
  bool SymmetricInIq() const { return kind != kSpline || spline.Folded() || spline.mirrored; }
  // Parameter combinations the surfaces do not depend on (the spline's
  // constant and its slope in id at the origin, removed by construction).
  int NullDirections() const { return kind == kSpline ? (spline.Folded() || spline.mirrored ? 2 : 3) : 0; }
  std::string Name() const {
    if (kind == kAnalytic) return "analytic";
    if (kind == kPoly) return "poly" + std::to_string(degree);
    if (spline.smoothing) return spline.symmetric ? "smooth" : "smooth-asym";
    return "spline" + std::to_string(spline.spans);
  }
};

template <typename T, typename P>
void FamilyFlux(const Family& f, const T& id, const T& iq, const P* p, T* psi_d, T* psi_q) {
  if (f.kind == Family::kAnalytic) {
    sim::SaturationFlux(id, iq, p, psi_d, psi_q);
  } else if (f.kind == Family::kPoly) {
    PolyFlux(f.degree, id, iq, p, psi_d, psi_q);
  } else {
    SplineFluxAndInductance<T>(f.spline, ScalarOf(id), ScalarOf(iq), p, psi_d, psi_q, nullptr, nullptr, nullptr);
  }
}

template <typename T, typename P>
void FamilyInductance(const Family& f, const T& id, const T& iq, const P* p, T* ldd, T* lqq, T* ldq) {
  if (f.kind == Family::kAnalytic) {
    sim::SaturationInductance(id, iq, p, ldd, lqq, ldq);
  } else if (f.kind == Family::kPoly) {
    PolyInductance(f.degree, id, iq, p, ldd, lqq, ldq);
  } else {
    SplineFluxAndInductance<T>(f.spline, ScalarOf(id), ScalarOf(iq), p, nullptr, nullptr, ldd, lqq, ldq);
  }
}

}  // namespace fluxcal::fit

#endif  // FLUXCAL_FITTING_FLUX_FAMILY_H_
