#include "identification/inductance.h"

#include <cmath>

#include <Eigen/Dense>

#include "absl/strings/str_cat.h"
#include "physics/hf.h"

namespace fluxcal::ident {
namespace {

using Complex = std::complex<double>;

// Unknowns x = (S, Re D, Im D, R); rows = Re/Im of (E1), Re/Im of (E2).
bool SolveE(Complex i0, Complex i1, Complex v, Complex vn, double w, double w2, Eigen::Vector4d* x) {
  const Complex j(0.0, 1.0);
  const Complex cS1 = j * w * i0, cD1 = j * w * std::conj(i1), cL1 = -w * std::conj(i1);
  const Complex cS2 = j * w2 * i1, cD2 = j * w2 * std::conj(i0), cL2 = -w2 * std::conj(i0);
  Eigen::Matrix4d A;
  A << cS1.real(), cD1.real(), cL1.real(), i0.real(),
       cS1.imag(), cD1.imag(), cL1.imag(), i0.imag(),
       cS2.real(), cD2.real(), cL2.real(), i1.real(),
       cS2.imag(), cD2.imag(), cL2.imag(), i1.imag();
  const Eigen::Vector4d b(v.real(), v.imag(), vn.real(), vn.imag());
  Eigen::FullPivLU<Eigen::Matrix4d> lu(A);
  if (!lu.isInvertible()) return false;
  *x = lu.solve(b);
  return true;
}

// Covariance of (Re I0, Im I0, Re I1, Im I1) from the circular complex one.
Eigen::Matrix4d RealCovariance(const PhasorCovariance& c) {
  Eigen::Matrix4d P = Eigen::Matrix4d::Zero();
  P(0, 0) = P(1, 1) = 0.5 * c.var_i0_a2;
  P(2, 2) = P(3, 3) = 0.5 * c.var_i1_a2;
  // E[a_r b_r] = E[a_i b_i] = Re C/2, E[a_r b_i] = -Im C/2, E[a_i b_r] = Im C/2.
  P(0, 2) = P(2, 0) = 0.5 * c.cov_i0_i1_a2.real();
  P(1, 3) = P(3, 1) = 0.5 * c.cov_i0_i1_a2.real();
  P(0, 3) = P(3, 0) = -0.5 * c.cov_i0_i1_a2.imag();
  P(1, 2) = P(2, 1) = 0.5 * c.cov_i0_i1_a2.imag();
  return P;
}

}  // namespace

absl::StatusOr<HfInductance> InductanceFromPhasors(Complex i0, Complex i1, Complex v, Complex vn, double w,
                                                   double w_e, const PhasorCovariance& cov) {
  const double w2 = 2.0 * w_e - w;
  if (std::abs(w2) < 1e-3 * std::abs(w)) {
    return absl::FailedPreconditionError(
        "field 'speed_rpm': 2 w_e equals the injection frequency; the negative sequence is DC");
  }
  Eigen::Vector4d x;
  if (!SolveE(i0, i1, v, vn, w, w2, &x)) {
    return absl::FailedPreconditionError("field 'i0_a': no HF response to solve for inductance");
  }
  HfInductance out;
  out.ldd_h = x(0) + x(1);
  out.lqq_h = x(0) - x(1);
  out.ldq_h = x(2);
  out.r_hf_ohm = x(3);
  // First-order propagation: central differences of the exact solve.
  Eigen::Matrix4d J;
  const double h = 1e-7 * std::max(std::abs(i0), 1e-9);
  for (int c = 0; c < 4; ++c) {
    Complex d0 = i0, d1 = i1, e0 = i0, e1 = i1;
    const Complex step = (c % 2 == 0) ? Complex(h, 0) : Complex(0, h);
    if (c < 2) { d0 += step; e0 -= step; } else { d1 += step; e1 -= step; }
    Eigen::Vector4d xp, xm;
    if (!SolveE(d0, d1, v, vn, w, w2, &xp) || !SolveE(e0, e1, v, vn, w, w2, &xm)) {
      return absl::FailedPreconditionError("field 'i0_a': ill-conditioned HF response");
    }
    J.col(c) = (xp - xm) / (2.0 * h);
  }
  Eigen::Matrix4d T;  // (S, ReD, ImD, R) -> (Ldd, Lqq, Ldq, R)
  T << 1, 1, 0, 0,
       1, -1, 0, 0,
       0, 0, 1, 0,
       0, 0, 0, 1;
  const Eigen::Matrix4d C = T * J * RealCovariance(cov) * J.transpose() * T.transpose();
  out.ldd_h_std = std::sqrt(std::max(0.0, C(0, 0)));
  out.lqq_h_std = std::sqrt(std::max(0.0, C(1, 1)));
  out.ldq_h_std = std::sqrt(std::max(0.0, C(2, 2)));
  out.r_hf_ohm_std = std::sqrt(std::max(0.0, C(3, 3)));
  return out;
}

absl::StatusOr<HfInductance> PaperInductance(Complex i0, Complex i1, double v, double w,
                                             const PhasorCovariance& cov) {
  const double a0 = std::abs(i0), a1 = std::abs(i1);
  if (!(a0 > a1) || !(v > 0) || !(w > 0)) {
    return absl::FailedPreconditionError(absl::StrCat(
        "field 'i0_a': eq. (8) needs |I0| > |I1| > 0, got |I0|=", a0, " |I1|=", a1));
  }
  HfInductance out;
  out.ldd_h = v / (w * (a0 + a1));
  out.lqq_h = v / (w * (a0 - a1));
  // Magnitude variance of a circular complex estimate: var|I| = var(I)/2.
  const double var_sum = 0.5 * (cov.var_i0_a2 + cov.var_i1_a2);
  out.ldd_h_std = out.ldd_h / (a0 + a1) * std::sqrt(var_sum);
  out.lqq_h_std = out.lqq_h / (a0 - a1) * std::sqrt(var_sum);
  return out;
}

void PredictPhasors(double ldd, double lqq, double ldq, double r, Complex v, Complex vn, double w,
                    double w_e, Complex* i0, Complex* i1) {
  // (E1)-(E2) without iron loss.
  physics::SolveHfPhasors(ldd, lqq, ldq, r, v, vn, w, w_e, 0.0, i0, i1);
}

}  // namespace fluxcal::ident
