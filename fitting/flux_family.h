// Flux-linkage model families for the fits, templated on the scalar so that
// Ceres differentiates the same equations the calibration evaluates.
//
// Every family is the gradient of a co-energy W'(id, iq), so the
// differential inductance (the Hessian) is symmetric by construction, and
// respects the machine's symmetry: psi_q(id, 0) = 0, psi_d(0, 0) = psi_pm.
//
//  kAnalytic: the twin's saturation model (simulation/saturation_model.h,
//    eq. (M1)), 7 parameters with the cross-saturation current scale ix_a
//    held fixed: psi_pm, Ld0, Lq0, Id_sat, Iq_sat, g_cross (, ix).
//  kPoly<N>: W' = psi_pm id + L0 I0^2 sum c_ab x^a y^b, x = id/I0, y = iq/I0,
//    over 2 <= a + b <= N with b even (so psi_q(id, 0) = 0 and no term
//    linear in id alone, so psi_d(0, 0) = psi_pm). L0 = 1e-4 H, I0 = 100 A
//    scale the coefficients to order one. Flexible: any smooth conservative
//    map is approximated as N grows; N is chosen by BIC.
#ifndef FLUXCAL_FITTING_FLUX_FAMILY_H_
#define FLUXCAL_FITTING_FLUX_FAMILY_H_

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

// Polynomial family. p[0] = psi_pm, p[1..] = c_ab in PolyTerms(n) order.
template <typename T, typename P>
void PolyFlux(int n, const T& id, const T& iq, const P* p, T* psi_d, T* psi_q) {
  const auto terms = PolyTerms(n);
  const T x = id / kPolyI0A, y = iq / kPolyI0A;
  T sd(0.0), sq(0.0);
  for (size_t k = 0; k < terms.size(); ++k) {
    const int a = terms[k].first, b = terms[k].second;
    if (a > 0) sd = sd + p[1 + k] * double(a) * IntPow(x, a - 1) * IntPow(y, b);
    if (b > 0) sq = sq + p[1 + k] * double(b) * IntPow(x, a) * IntPow(y, b - 1);
  }
  *psi_d = p[0] + kPolyL0H * kPolyI0A * sd;
  *psi_q = kPolyL0H * kPolyI0A * sq;
}

template <typename T, typename P>
void PolyInductance(int n, const T& id, const T& iq, const P* p, T* ldd, T* lqq, T* ldq) {
  const auto terms = PolyTerms(n);
  const T x = id / kPolyI0A, y = iq / kPolyI0A;
  T dd(0.0), qq(0.0), dq(0.0);
  for (size_t k = 0; k < terms.size(); ++k) {
    const int a = terms[k].first, b = terms[k].second;
    if (a > 1) dd = dd + p[1 + k] * double(a * (a - 1)) * IntPow(x, a - 2) * IntPow(y, b);
    if (b > 1) qq = qq + p[1 + k] * double(b * (b - 1)) * IntPow(x, a) * IntPow(y, b - 2);
    if (a > 0 && b > 0) dq = dq + p[1 + k] * double(a * b) * IntPow(x, a - 1) * IntPow(y, b - 1);
  }
  *ldd = kPolyL0H * dd;
  *lqq = kPolyL0H * qq;
  *ldq = kPolyL0H * dq;
}

// A family instance: "analytic" or "poly<N>".
struct Family {
  enum Kind { kAnalytic, kPoly } kind = kAnalytic;
  int degree = 0;   // kPoly only
  int NumParams() const {
    return kind == kAnalytic ? sim::kSaturationParams : 1 + static_cast<int>(PolyTerms(degree).size());
  }
  std::string Name() const {
    return kind == kAnalytic ? "analytic" : "poly" + std::to_string(degree);
  }
};

template <typename T, typename P>
void FamilyFlux(const Family& f, const T& id, const T& iq, const P* p, T* psi_d, T* psi_q) {
  if (f.kind == Family::kAnalytic) {
    sim::SaturationFlux(id, iq, p, psi_d, psi_q);
  } else {
    PolyFlux(f.degree, id, iq, p, psi_d, psi_q);
  }
}

template <typename T, typename P>
void FamilyInductance(const Family& f, const T& id, const T& iq, const P* p, T* ldd, T* lqq, T* ldq) {
  if (f.kind == Family::kAnalytic) {
    sim::SaturationInductance(id, iq, p, ldd, lqq, ldq);
  } else {
    PolyInductance(f.degree, id, iq, p, ldd, lqq, ldq);
  }
}

}  // namespace fluxcal::fit

#endif  // FLUXCAL_FITTING_FLUX_FAMILY_H_
