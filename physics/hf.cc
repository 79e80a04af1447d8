#include "physics/hf.h"

#include <Eigen/Dense>

namespace fluxcal::physics {

using Complex = std::complex<double>;

void HfBranch(double ldd, double lqq, double ldq, double w, double g, Complex* S, Complex* D) {
  const Complex j(0.0, 1.0);
  Complex mdd = j * w * ldd, mqq = j * w * lqq, mdq = j * w * ldq;
  if (g != 0.0) {
    // N = I + jw g L; M = jwL N^-1.
    const Complex a = 1.0 + j * w * g * ldd, b = j * w * g * ldq, d = 1.0 + j * w * g * lqq;
    const Complex det = a * d - b * b;
    const Complex ia = d / det, ib = -b / det, id = a / det;
    const Complex ndd = mdd * ia + mdq * ib, ndq = mdd * ib + mdq * id, nqq = mdq * ib + mqq * id;
    mdd = ndd; mdq = ndq; mqq = nqq;
  }
  *S = 0.5 * (mdd + mqq);
  *D = 0.5 * (mdd - mqq) + j * mdq;
}

void SolveHfPhasors(double ldd, double lqq, double ldq, double r, Complex v, Complex vn, double w_i, double w_e,
                    double g_fe, Complex* i0, Complex* i1) {
  const double w2 = 2.0 * w_e - w_i;
  Complex S1, D1, S2, D2;
  HfBranch(ldd, lqq, ldq, w_i, g_fe, &S1, &D1);
  HfBranch(ldd, lqq, ldq, w2, g_fe, &S2, &D2);
  const Complex a1 = r + S1, b1 = D1, a2 = r + S2, b2 = D2;
  // Unknowns (Re I0, Im I0, Re I1, Im I1); (E1)-(E2) are real-linear in them:
  // a X for X = xr + j xi: real [a_r, -a_i], imag [a_i, a_r];
  // b conj(X): real [b_r, b_i], imag [b_i, -b_r].
  Eigen::Matrix4d A;
  A << a1.real(), -a1.imag(), b1.real(), b1.imag(),
       a1.imag(), a1.real(), b1.imag(), -b1.real(),
       b2.real(), b2.imag(), a2.real(), -a2.imag(),
       b2.imag(), -b2.real(), a2.imag(), a2.real();
  const Eigen::Vector4d x = A.partialPivLu().solve(Eigen::Vector4d(v.real(), v.imag(), vn.real(), vn.imag()));
  *i0 = Complex(x(0), x(1));
  *i1 = Complex(x(2), x(3));
}

}  // namespace fluxcal::physics
