// HF rotating-injection demodulators on plain arrays.
//
// Signal model (docs/identification.md, eq. (D1)): with the amplitude-
// invariant Clarke transform i_s = i_alpha + j i_beta,
//   i_s(t_k) = I0 e^{j w_i t_k} + I1 e^{j(2 theta_e(t_k) - w_i t_k)}
//              + (c0 + c1 (t_k - t_mid)) e^{j theta_e(t_k)} + noise,
// t_k = k / f_sample_hz. I0 is the positive-sequence, I1 the negative-sequence
// HF phasor; c0 (+ drift c1) is the fundamental current in dq.
#ifndef FLUXCAL_IDENTIFICATION_DEMOD_H_
#define FLUXCAL_IDENTIFICATION_DEMOD_H_

#include <complex>
#include <cstddef>

#include "absl/status/statusor.h"

namespace fluxcal::ident {

using Complex = std::complex<double>;

// Samples of one operating point. Pointers to n values each.
struct PhaseSamples {
  const double* ia_a = nullptr;
  const double* ib_a = nullptr;
  const double* ic_a = nullptr;
  const double* theta_e_rad = nullptr;   // measured, wrapped or unwrapped
  size_t n = 0;
  double f_sample_hz = 0.0;
  double f_injection_hz = 0.0;
};

struct PhasorEstimate {
  Complex i0_a, i1_a;                    // HF phasors at t = 0 (first sample)
  // Covariance of the complex estimates, E[e e^H] (circular): var(I0),
  // var(I1), cov(I0, I1). Real and imaginary parts each carry half.
  double var_i0_a2 = 0, var_i1_a2 = 0;
  Complex cov_i0_i1_a2;
  Complex fundamental_dq_a;              // c0: mean dq current of the window
  Complex fundamental_drift_a_per_s;     // c1
  double residual_rms_a = 0;             // RMS of the complex residual
  // Residual power at other harmonics of the injection (-w_i, +-3 w_i,
  // +-5 w_i) relative to |I0|^2: distortion such as dead time or sensor
  // gain errors (LsqDemodulate only).
  double harmonic_ratio = 0;
  double w_e_rad_s = 0;                  // electrical speed from theta slope
  // An uncompensated dead time at speed: each phase current's zero
  // crossings (six per electrical period) gate the HF voltage error, which
  // puts sidebands at orders +-6, +-12 of theta_e about both phasors; the
  // gate's mean, of the same size, lies on the phasors themselves. The
  // largest sideband's amplitude over |I0| (LsqDemodulate only; NaN at
  // standstill or where 6 w_e is under two Fourier bins of the window).
  double dead_time_sideband_ratio = 0;
  size_t samples_used = 0;
  double periods_used = 0;
};

// Whole injection periods that fit in n samples, and the sample count they
// span (rounded to the nearest sample).
size_t WholePeriodSamples(size_t n, double f_sample_hz, double f_injection_hz, double* periods);

// Least-squares electrical speed (rad/s) from the unwrapped measured angle.
double EstimateSpeedRadPerS(const double* theta_e_rad, size_t n, double f_sample_hz);

// Closed-form complex least squares of model (D1) over whole injection
// periods. Errors: InvalidArgument for fewer than 2 periods or bad rates.
absl::StatusOr<PhasorEstimate> LsqDemodulate(const PhaseSamples& s);

// The paper's pipeline (Wu, Wu, Zhu 2013, Sec. 3.2, Fig. 3): two cascaded
// delay filters D(x)_k = x_k - x_{k-M}, M = half an injection period; frame
// at +w_i and low-pass (moving average over one period) -> I0; remove it
// (high-pass); frame at (2 theta_e - w_i t) and low-pass -> I1. When
// `compensate` the cascade's gain and phase H(w)^2 = (1 - e^{-j w M Ts})^2
// are divided out at each component's actual frequency (w_i for I0,
// 2 w_e - w_i for I1); otherwise the nominal gain 4 (the paper's "amplified
// 4 times") is divided out. Standard errors from the scatter of per-period
// means (batch means).
absl::StatusOr<PhasorEstimate> PaperDemodulate(const PhaseSamples& s, bool compensate = true);

// Fits the recorded command over the same window, with the regressors of
// the current's model (D1):
//   u_alpha + j u_beta = V e^{j w_i t} + Vn e^{j(2 theta_e - w_i t)}
//                        + (f0 + f1 (t - t_mid)) e^{j theta_e}.
// V is the injection; Vn the command at the negative sequence's frequency
// w_2 = 2 w_e - w_i: a bench current loop that answers the HF current
// there puts it on the command (docs/identification.md, Sec. 8), and (E2)
// needs it on its left-hand side.
struct VoltageEstimate {
  Complex v_cmd_v;                       // commanded injection phasor at t = 0
  Complex v_neg_cmd_v;                   // commanded negative-sequence phasor Vn
  Complex fundamental_dq_v;              // mean fundamental command in dq
};
absl::StatusOr<VoltageEstimate> FitCommandVoltage(const double* ualpha_v, const double* ubeta_v,
                                                  const double* theta_e_rad, size_t n,
                                                  double f_sample_hz, double f_injection_hz);

// Effective voltage phasor seen by the machine at sample instants for a
// command applied one PWM period late as a zero-order hold
// (docs/identification.md eq. (V1)): V_eff = V_cmd e^{-j 1.5 w T} x / sin x,
// x = w T / 2, T = 1 / f_pwm_hz. w is the component's own frequency in
// the stationary frame (w_i for V, w_2 = 2 w_e - w_i for Vn).
Complex EffectiveVoltage(Complex v_cmd_v, double w_rad_s, double f_pwm_hz);

}  // namespace fluxcal::ident

#endif  // FLUXCAL_IDENTIFICATION_DEMOD_H_
