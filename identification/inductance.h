// From HF current phasors to the differential inductance matrix, and back.
//
// Derivation (docs/identification.md, Sec. 2): in the stationary frame the
// HF flux of a machine whose dq differential inductance is the symmetric
// matrix L = [[Ldd, Ldq], [Ldq, Lqq]] is
//   psi_s = S i_s + D e^{j 2 theta_e} conj(i_s),
//   S = (Ldd + Lqq)/2,  D = (Ldd - Lqq)/2 + j Ldq,
// and u_s = R i_s + d psi_s/dt. With u_s = V e^{j w_i t} + Vn e^{j(2 theta_e - w_i t)}
// and i_s = I0 e^{j w_i t} + I1 e^{j(2 theta_e - w_i t)}, theta_e = theta_0 + w_e t:
//   (E1)  V  = R I0 + j w_i (S I0 + D conj(I1))
//   (E2)  Vn = R I1 + j w_2 (S I1 + D conj(I0)),   w_2 = 2 w_e - w_i.
// Vn is what the bench's command carries at w_2 (demod.h FitCommandVoltage);
// the paper takes it as zero.
// Both are linear in (S, Re D, Im D, R): four real equations, four unknowns.
// With R = 0 and Ldq = 0 they reduce to the paper's eq. (8):
//   Ld = V / (w_i (|I0| + |I1|)),  Lq = V / (w_i (|I0| - |I1|)).
#ifndef FLUXCAL_IDENTIFICATION_INDUCTANCE_H_
#define FLUXCAL_IDENTIFICATION_INDUCTANCE_H_

#include <complex>

#include "absl/status/statusor.h"

namespace fluxcal::ident {

struct HfInductance {
  double ldd_h = 0, lqq_h = 0, ldq_h = 0, r_hf_ohm = 0;
  double ldd_h_std = 0, lqq_h_std = 0, ldq_h_std = 0, r_hf_ohm_std = 0;
};

// Phasor uncertainty (circular complex covariance, see demod.h).
struct PhasorCovariance {
  double var_i0_a2 = 0, var_i1_a2 = 0;
  std::complex<double> cov_i0_i1_a2;
};

// Solves (E1)-(E2) exactly for Ldd, Lqq, Ldq and R; standard errors by
// first-order propagation of the phasor covariance. `v_eff_v` and
// `v_neg_eff_v` are the effective voltage phasors of the injection and of
// the negative sequence (demod.h EffectiveVoltage at w_i and w_2).
// FailedPrecondition when the system is singular (no HF response).
absl::StatusOr<HfInductance> InductanceFromPhasors(std::complex<double> i0_a,
                                                   std::complex<double> i1_a,
                                                   std::complex<double> v_eff_v,
                                                   std::complex<double> v_neg_eff_v, double w_i_rad_s,
                                                   double w_e_rad_s,
                                                   const PhasorCovariance& cov = {});

// The paper's eq. (8) from phasor magnitudes: Ldd, Lqq only (Ldq = R = 0).
absl::StatusOr<HfInductance> PaperInductance(std::complex<double> i0_a, std::complex<double> i1_a,
                                             double v_amplitude_v, double w_i_rad_s,
                                             const PhasorCovariance& cov = {});

// Forward model: the phasors (I0, I1) that (E1)-(E2) predict.
void PredictPhasors(double ldd_h, double lqq_h, double ldq_h, double r_ohm,
                    std::complex<double> v_eff_v, std::complex<double> v_neg_eff_v, double w_i_rad_s,
                    double w_e_rad_s,
                    std::complex<double>* i0_a, std::complex<double>* i1_a);

}  // namespace fluxcal::ident

#endif  // FLUXCAL_IDENTIFICATION_INDUCTANCE_H_
