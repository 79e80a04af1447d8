// Affine arithmetic for the fits' linear families (internal to fitting/).
//
// An affine form c + sum_j a_j p_j in the parameters. The polynomial and
// spline families are linear in their coefficients, so evaluating the very
// cost functors Ceres differentiates (fitting/*_residual.h) with T = Affine
// gives each residual's value at p = 0 and its exact, sparse gradient in one
// pass: a spline residual touches 25 of ~145 coefficients, where the
// dynamic-size autodiff carried all of them through every evaluation. Only
// products with a constant exist in those families; anything else is a
// programming error (the analytic family never takes this path) and aborts.
//
// The type and its operators live in their own namespace: the sqrt below
// would otherwise hide std::sqrt from unqualified calls in the code around
// it. The family templates find them by argument-dependent lookup.
#ifndef FLUXCAL_FITTING_AFFINE_H_
#define FLUXCAL_FITTING_AFFINE_H_

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <utility>

#include "absl/container/inlined_vector.h"

namespace fluxcal::fit::affine {

struct Affine {
  double c = 0;
  // Inline storage: the one-term forms p_j * a (most of them) never allocate.
  absl::InlinedVector<std::pair<int, double>, 2> t;
  Affine() = default;
  Affine(double v) : c(v) {}  // NOLINT: T(0.0), T(id) in the templates
  bool Constant() const { return t.empty(); }
};
inline Affine operator*(Affine a, double s) {
  a.c *= s;
  for (auto& x : a.t) x.second *= s;
  return a;
}
inline Affine operator*(double s, Affine a) { return std::move(a) * s; }
inline Affine operator+(Affine a, const Affine& b) {
  a.c += b.c;
  a.t.insert(a.t.end(), b.t.begin(), b.t.end());
  return a;
}
inline Affine operator-(const Affine& a) { return a * -1.0; }
inline Affine operator-(Affine a, const Affine& b) {
  a.c -= b.c;
  for (const auto& x : b.t) a.t.push_back({x.first, -x.second});
  return a;
}
inline Affine& operator+=(Affine& a, const Affine& b) {
  a.c += b.c;
  a.t.insert(a.t.end(), b.t.begin(), b.t.end());
  return a;
}
inline Affine operator*(const Affine& a, const Affine& b) {
  if (b.Constant()) return a * b.c;
  if (a.Constant()) return b * a.c;
  std::fprintf(stderr, "fit: a product of parameters in a linear family\n");
  std::abort();
}
inline Affine operator/(const Affine& a, double s) { return a * (1.0 / s); }
inline Affine operator/(const Affine& a, const Affine& b) {
  if (b.Constant()) return a * (1.0 / b.c);
  std::fprintf(stderr, "fit: division by a parameter in a linear family\n");
  std::abort();
}
inline Affine sqrt(const Affine& a) {
  if (a.Constant()) return Affine(std::sqrt(a.c));
  std::fprintf(stderr, "fit: sqrt of a parameter in a linear family\n");
  std::abort();
}
// The operating point of a spline basis is data (flux_family.h, ScalarOf).
inline double ScalarOf(const Affine& a) { return a.c; }

}  // namespace fluxcal::fit::affine

#endif  // FLUXCAL_FITTING_AFFINE_H_
