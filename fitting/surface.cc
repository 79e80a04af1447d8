#include "fitting/surface.h"

#include <cmath>
#include <limits>
#include <map>

#include "ceres/jet.h"
#include "simulation/saturation_model.h"

namespace fluxcal::fit {
namespace {

using Grad = std::array<double, kSurfaceValues>;

// Accumulates d value / d params[index] (folded spline bases repeat an
// index).
class GradAccumulator {
 public:
  void Add(int index, int value, double d) {
    if (d != 0.0) g_[index][value] += d;
  }
  std::vector<std::pair<int, Grad>> Take() {
    std::vector<std::pair<int, Grad>> out(g_.begin(), g_.end());
    return out;
  }

 private:
  std::map<int, Grad> g_;
};

// The spline co-energy of flux_family.h (SplineFluxAndInductance), written
// out per coefficient: psi_d = p0 + kW (sum c B_i' E_j - the same at the
// origin), psi_q = kW (sum c B_i E_j' [- at the origin when not folded]),
// Ldd = kW sum c B_i'' E_j, Lqq = kW sum c B_i E_j'', Ldq = kW sum c B_i' E_j'.
// The mirrored layout evaluates S at q = |iq| (psi_q and Ldq take the sign
// of iq) and its pivot coefficient is a combination of the free ones
// (MirrorConstraint::Terms): the gradient spreads over them.
void SplineAt(const SplineDomain& dom, const double* p, double id, double iq, SurfacePoint* out) {
  const int ne = dom.NumEven();
  const bool mirrored = dom.mirrored && dom.smoothing && dom.symmetric;
  const MirrorConstraint mc(dom);
  const double sign = mirrored && iq < 0 ? -1.0 : 1.0;
  const double q = mirrored ? std::abs(iq) : iq;
  // Calls add(parameter index, weight) for full coefficient (i, j).
  auto terms = [&](int i, int j, auto add) {
    if (mirrored) {
      mc.Terms(j, [&](int e, double w) { add(1 + i * ne + e, w); });
    } else {
      add(1 + i * ne + dom.QIndex(j), 1.0);
    }
  };
  const double kW = kPolyL0H * kPolyI0A * kPolyI0A;
  const Basis1d bd = EvalBasis(id, dom.id_lo_a, dom.id_hi_a, dom.spans);
  const Basis1d bq = EvalBasis(q, dom.IqLo(), dom.iq_hi_a, dom.SpansQ());
  const Basis1d b0d = EvalBasis(0.0, dom.id_lo_a, dom.id_hi_a, dom.spans);
  const Basis1d b0q = EvalBasis(0.0, dom.IqLo(), dom.iq_hi_a, dom.SpansQ());
  GradAccumulator acc;
  auto& v = out->value;
  v = {};
  v[kPsiD] = p[0];
  acc.Add(0, kPsiD, 1.0);
  for (int a = 0; a <= kSplineDegree; ++a) {
    for (int c = 0; c <= kSplineDegree; ++c) {
      const double w[kSurfaceValues] = {kW * bd.d1[a] * bq.v[c], sign * kW * bd.v[a] * bq.d1[c],
                                        kW * bd.d2[a] * bq.v[c], kW * bd.v[a] * bq.d2[c],
                                        sign * kW * bd.d1[a] * bq.d1[c]};
      terms(bd.first + a, bq.first + c, [&](int idx, double t) {
        for (int s = 0; s < kSurfaceValues; ++s) {
          v[s] += p[idx] * t * w[s];
          acc.Add(idx, s, t * w[s]);
        }
      });
      const double w0d = -kW * b0d.d1[a] * b0q.v[c];
      const double w0q = dom.Folded() || mirrored ? 0.0 : -kW * b0d.v[a] * b0q.d1[c];
      terms(b0d.first + a, b0q.first + c, [&](int idx0, double t) {
        v[kPsiD] += p[idx0] * t * w0d;
        acc.Add(idx0, kPsiD, t * w0d);
        if (w0q != 0.0) {
          v[kPsiQ] += p[idx0] * t * w0q;
          acc.Add(idx0, kPsiQ, t * w0q);
        }
      });
    }
  }
  out->grad = acc.Take();
}

// The polynomial co-energy of flux_family.h (PolyFlux, PolyInductance) per
// coefficient.
void PolyAt(int n, const double* p, double id, double iq, SurfacePoint* out) {
  const auto terms = PolyTerms(n);
  const double x = id / kPolyI0A, y = iq / kPolyI0A;
  auto& v = out->value;
  v = {};
  v[kPsiD] = p[0];
  out->grad.clear();
  out->grad.push_back({0, Grad{1.0, 0, 0, 0, 0}});
  for (size_t k = 0; k < terms.size(); ++k) {
    const int a = terms[k].first, b = terms[k].second;
    Grad w{};
    if (a > 0) w[kPsiD] = kPolyL0H * kPolyI0A * a * IntPow(x, a - 1) * IntPow(y, b);
    if (b > 0) w[kPsiQ] = kPolyL0H * kPolyI0A * b * IntPow(x, a) * IntPow(y, b - 1);
    if (a > 1) w[kLdd] = kPolyL0H * a * (a - 1) * IntPow(x, a - 2) * IntPow(y, b);
    if (b > 1) w[kLqq] = kPolyL0H * b * (b - 1) * IntPow(x, a) * IntPow(y, b - 2);
    if (a > 0 && b > 0) w[kLdq] = kPolyL0H * a * b * IntPow(x, a - 1) * IntPow(y, b - 1);
    for (int s = 0; s < kSurfaceValues; ++s) v[s] += p[1 + k] * w[s];
    out->grad.push_back({static_cast<int>(1 + k), w});
  }
}

// The analytic family (simulation/saturation_model.h), differentiated by
// ceres::Jet over its parameters.
void AnalyticAt(const double* p, double id, double iq, SurfacePoint* out) {
  using J = ceres::Jet<double, sim::kSaturationParams>;
  J pj[sim::kSaturationParams];
  for (int k = 0; k < sim::kSaturationParams; ++k) pj[k] = J(p[k], k);
  J pd, pq, ldd, lqq, ldq;
  sim::SaturationFlux(J(id), J(iq), pj, &pd, &pq);
  sim::SaturationInductance(J(id), J(iq), pj, &ldd, &lqq, &ldq);
  const J* vals[kSurfaceValues] = {&pd, &pq, &ldd, &lqq, &ldq};
  out->grad.clear();
  for (int s = 0; s < kSurfaceValues; ++s) out->value[s] = vals[s]->a;
  for (int k = 0; k < sim::kSaturationParams; ++k) {
    Grad g;
    for (int s = 0; s < kSurfaceValues; ++s) g[s] = vals[s]->v[k];
    out->grad.push_back({k, g});
  }
}

}  // namespace

SurfacePoint SurfaceAt(const Family& f, const double* params, double id_a, double iq_a) {
  SurfacePoint out;
  if (!std::isfinite(id_a) || !std::isfinite(iq_a)) {
    out.value.fill(std::numeric_limits<double>::quiet_NaN());
    return out;
  }
  if (f.kind == Family::kSpline) {
    SplineAt(f.spline, params, id_a, iq_a, &out);
  } else if (f.kind == Family::kPoly) {
    PolyAt(f.degree, params, id_a, iq_a, &out);
  } else {
    AnalyticAt(params, id_a, iq_a, &out);
  }
  return out;
}

// Roughness of a smoothing-spline co-energy: every third derivative of W,
//   R = int W_ddd^2 + 3 W_ddq^2 + 3 W_dqq^2 + W_qqq^2  (did diq),
// the squared norm of the third-derivative tensor (binomial weights count
// its equal mixed entries). On uniform knots the a-th derivative of a
// B-spline expansion is, to leading order, the a-th difference of its
// coefficients over h^a (de Boor, A Practical Guide to Splines, X(12);
// the P-spline penalty of Eilers & Marx, Stat. Sci. 11 (1996)), so each row
// is Delta_d^a Delta_q^b c / (h_d^a h_q^b) over the whole coefficient grid,
// measured region or not. The penalty's null space is W quadratic, i.e. a
// constant inductance: where no data pull, the surface continues with the
// inductance it has at the data's edge, and a strong lambda flattens
// towards the best constant-inductance model instead of oscillating.
// Anisotropy (kappa, surface.h): a tensor-product smooth has one weight per
// direction (Wood 2006, Biometrics 62(4), "low-rank scale-invariant tensor
// product smooths"): a machine saturates along iq over a few amperes where
// its Ldd barely moves along id, and one isotropic weight must either
// follow the q knee and let Ldd wiggle with the noise between the measured
// id columns, or flatten the knee. Row (a, b) is scaled by kappa^((b-a)/12),
// its square by kappa^((b-a)/6); the null space (a constant inductance) is
// the same for every kappa. The fit chooses kappa with lambda
// (solve_linear.cc, select.cc).
// The inductance's curvature (`curvature_weight` mu): W's third derivatives
// are the inductance's slopes, and a penalty on slopes alone prices a
// wiggle of the inductance between the measured points (wavelength l,
// amplitude A: ~A^2 (2 pi / l)^2 per unit length) like a knee of the same
// height. Fourth derivatives, the inductance's curvature, price the wiggle
// (2 pi u / l)^2 times more than its slope term does, u the knot spacing
// (the rows' common current unit):
//   R = int |nabla^3 W|^2 + mu u^2 (W_dddd^2 + 4 W_dddq^2 + 6 W_ddqq^2 + 4 W_dqqq^2)
// (binomial weights as above). mu = 1 weighs the inductance's slope and
// its change over one knot spacing alike: wiggles shorter than ~2 pi knot
// spacings (the measured points lie 1-2 spacings apart) cost mostly
// curvature, a knee mostly slope. W_qqqq, Lqq's own curvature along iq, is
// left out: that is where a machine's sharpest knee lies (bridges and ribs
// saturating within a few amperes, Lqq falling up to 10x), and pricing its
// curvature spread the knee: the bridge-knee twin end to end went from
// 0.52-0.57 % to 0.52-0.67 % with it, 0.40-0.44 % without
// (docs/fitting.md, "The inductance's curvature"). On uniform knots the
// fourth difference of a quartic spline's coefficients over h^4 is its
// fourth derivative on a span (de Boor, as above). Each added term's null
// space contains the third-order one's, so the sum's null space is still a
// constant inductance (extrapolation unchanged) and the likelihoods stay
// comparable across kappa. The anisotropy scales both orders alike
// (kappa^-1/12 per id derivative, kappa^1/12 per iq derivative: a change
// of the axes' metric).
SurfaceEvaluator::SurfaceEvaluator(const Family& f, std::vector<double> params) : f_(f), p_(std::move(params)) {
  if (f_.kind == Family::kSpline && static_cast<int>(p_.size()) == f_.NumParams()) {
    spline_ = SplineSurface(f_.spline, p_.data());
  }
}

void SurfaceEvaluator::Eval(double id, double iq, double* psi_d, double* psi_q, double* ldd, double* lqq,
                            double* ldq) const {
  if (!spline_.empty()) {
    spline_.Eval(id, iq, psi_d, psi_q, ldd, lqq, ldq);
    return;
  }
  if (psi_d != nullptr) FamilyFlux(f_, id, iq, p_.data(), psi_d, psi_q);
  if (ldd != nullptr) FamilyInductance(f_, id, iq, p_.data(), ldd, lqq, ldq);
}

Eigen::MatrixXd SmoothingPenalty(const Family& fam, double anisotropy_q, double curvature_weight) {
  if (fam.kind != Family::kSpline || !fam.spline.smoothing) return Eigen::MatrixXd(0, fam.NumParams());
  const SplineDomain& dom = fam.spline;
  const int nd = dom.NumD(), nq = dom.NumQ(), ne = dom.NumEven(), k = fam.NumParams();
  // The mirrored layout's coefficients are constrained (MirrorConstraint):
  // the differences are of the full coefficients, expressed in the free ones.
  const MirrorConstraint mirror(dom);
  const double hd = (dom.id_hi_a - dom.id_lo_a) / dom.spans, hq = (dom.iq_hi_a - dom.IqLo()) / dom.SpansQ();
  // Binomial difference stencils of order 0..4.
  const std::vector<std::vector<double>> stencil = {{1}, {-1, 1}, {1, -2, 1}, {-1, 3, -3, 1}, {1, -4, 6, -4, 1}};
  // A common current unit keeps the rows of order one.
  const double unit = std::max(hd, hq);
  std::vector<Eigen::VectorXd> rows;
  // Rows of one order: sqrt(w_order C(order, a)) Delta_d^a Delta_q^b c
  // (unit/h_d)^a (unit/h_q)^b kappa^((b-a)/12), a + b = order.
  auto add_order = [&](int order, double w_order) {
    for (int a = order; a >= 0; --a) {
      const int bq = order - a;
      // Not W_qqqq, Lqq's own curvature along iq: the q knee (below).
      if (order == 4 && a == 0) continue;
      double binom = 1;
      for (int t = 0; t < a; ++t) binom = binom * (order - t) / (t + 1);
      const double scale = std::sqrt(w_order * binom) * std::pow(unit / hd, a) * std::pow(unit / hq, bq) *
                           std::pow(anisotropy_q, (bq - a) / 12.0);
      for (int i = 0; i + a < nd; ++i) {
        for (int j = 0; j + bq < nq; ++j) {
          Eigen::VectorXd row = Eigen::VectorXd::Zero(k);
          for (int u = 0; u <= a; ++u)
            for (int v = 0; v <= bq; ++v)
              if (dom.mirrored) {
                mirror.Terms(j + v, [&](int e, double w) {
                  row(1 + (i + u) * ne + e) += w * scale * stencil[a][u] * stencil[bq][v];
                });
              } else {
                row(1 + (i + u) * ne + dom.QIndex(j + v)) += scale * stencil[a][u] * stencil[bq][v];
              }
          rows.push_back(row);
        }
      }
    }
  };
  add_order(3, 1.0);
  if (curvature_weight > 0) add_order(4, curvature_weight);
  Eigen::MatrixXd P(rows.size(), k);
  for (size_t r = 0; r < rows.size(); ++r) P.row(r) = rows[r].transpose();
  return P;
}

}  // namespace fluxcal::fit
