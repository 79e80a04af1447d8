// The HF phasor forward model (docs/identification.md, Sec. 2;
// identification/inductance.h): in the stationary frame the HF flux of a
// machine with the symmetric dq differential inductance L is
//   psi_s = S i_s + D e^{j 2 theta_e} conj(i_s),
//   S = (Ldd + Lqq)/2,  D = (Ldd - Lqq)/2 + j Ldq,
// and with a voltage on both sequences (injection V at w_i, negative
// sequence Vn at w_2 = 2 w_e - w_i):
//   (E1)  V  = R I0 + (S1 I0 + D1 conj(I1)),
//   (E2)  Vn = R I1 + (S2 I1 + D2 conj(I0)),
// where (S_k, D_k) are the sequence coefficients of the magnetising branch
// at w_k: j w L alone, or with iron loss g = 1 / R_fe in parallel,
// j w L (I + j w g L)^-1 (a complex symmetric matrix M; it acts on a
// sequence's phasor as S_M I + D_M conj(I_other) with S_M = (M_dd + M_qq)/2,
// D_M = (M_dd - M_qq)/2 + j M_dq; derivation: docs/diagnosis.md, "Iron loss").
// Double-only (the one exception to the kernel's Jet rule): the 4x4 real solve lives in hf.cc (Eigen stays out of the
// header).
#ifndef FLUXCAL_PHYSICS_HF_H_
#define FLUXCAL_PHYSICS_HF_H_

#include <complex>

namespace fluxcal::physics {

// Sequence coefficients (S_M, D_M) of the magnetising branch at w_rad_s.
void HfBranch(double ldd_h, double lqq_h, double ldq_h, double w_rad_s, double g_fe_s, std::complex<double>* s,
              std::complex<double>* d);

// The phasors (I0, I1) that (E1)-(E2) predict for injection v_v at w_i_rad_s
// and negative-sequence voltage vn_v, at electrical speed w_e_rad_s.
void SolveHfPhasors(double ldd_h, double lqq_h, double ldq_h, double r_ohm, std::complex<double> v_v,
                    std::complex<double> vn_v, double w_i_rad_s, double w_e_rad_s, double g_fe_s,
                    std::complex<double>* i0_a, std::complex<double>* i1_a);

}  // namespace fluxcal::physics

#endif  // FLUXCAL_PHYSICS_HF_H_
