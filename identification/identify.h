// Set-level HF identification: one result per operating point of a
// recording set (docs/recording-format.md), by the paper's method or the
// least-squares demodulator with the exact 2x2 inversion.
#ifndef FLUXCAL_IDENTIFICATION_IDENTIFY_H_
#define FLUXCAL_IDENTIFICATION_IDENTIFY_H_

#include <complex>
#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "io/recording_set.h"

namespace fluxcal::ident {

enum class Method { kPaper, kLsq };

// Parses "paper" / "lsq".
absl::StatusOr<Method> ParseMethod(const std::string& name);
const char* MethodName(Method m);

struct HfPointResult {
  std::string point;
  double id_a = 0, iq_a = 0;            // measured mean dq current of the window
  double speed_rpm = 0;                 // from the measured angle
  double temperature_c = 25.0;
  // Differential inductance: ld_h = Ldd, lq_h = Lqq, ldq_h = Ldq.
  double ld_h = 0, lq_h = 0, ldq_h = 0, r_hf_ohm = 0;
  double ld_h_std = 0, lq_h_std = 0, ldq_h_std = 0, r_hf_ohm_std = 0;
  bool has_ldq = false;                 // false for the paper's method (eq. (8))
  std::complex<double> i0_a, i1_a;      // HF phasors (t = first sample)
  std::complex<double> v_eff_v;         // effective injection voltage phasor
  // Effective negative-sequence voltage phasor (the command at w_2 =
  // 2 w_e - w_i, demod.h FitCommandVoltage), on (E2)'s left-hand side.
  std::complex<double> v_neg_eff_v;
  // Quality.
  double residual_rms_a = 0;            // LSQ model residual (complex RMS)
  double snr_db = 0;                    // 10 log10(|I0|^2 / residual power)
  double harmonic_ratio = 0;            // residual power at other HF harmonics / |I0|^2
  double periods_used = 0;
  double near_zero_fraction = 0;        // samples with a phase current within the HF ripple of 0
  // Rotating points: the dead-time sidebands over |I0| (demod.h); NaN
  // where not resolved (standstill, 6 w_e under two bins of the window).
  double dead_time_sideband_ratio = std::numeric_limits<double>::quiet_NaN();
  bool clipped = false;
  bool reliable = true;
  std::vector<std::string> flags;       // why a point is unreliable
  std::string failure;                  // set when the flag identification_failed is
};

struct IdentifyOptions {
  Method method = Method::kLsq;
  // Delay filters' exact frequency compensation (paper method only).
  bool compensate_delay_filters = true;
  // Progress callback (point index, count), e.g. for stderr output.
  std::function<void(size_t, size_t)> progress;
  // Polled before each point: true stops the set with Cancelled (a
  // server's client deadline passed; plain callback, no RPC types here).
  std::function<bool()> cancelled;
};

// The share of samples with a phase current within half the HF ripple of
// zero beyond which a point is flagged phase_current_near_zero (where the
// dead-time sidebands are not resolved): 5 %, where the dead-time
// distortion of the HF voltage becomes visible in the identified
// inductance (the paper's Sec. 3.3).
inline constexpr double kNearZeroFraction = 0.05;

absl::StatusOr<HfPointResult> IdentifyPoint(const io::RecordingSet& set, size_t point,
                                            const IdentifyOptions& options);

// Every waveform point of the set, in manifest order. Malformed input is an
// error naming the point; a point whose HF response cannot be inverted comes
// back with NaN values, reliable = false and the flag identification_failed.
absl::StatusOr<std::vector<HfPointResult>> IdentifySet(const io::RecordingSet& set,
                                                       const IdentifyOptions& options);

}  // namespace fluxcal::ident

#endif  // FLUXCAL_IDENTIFICATION_IDENTIFY_H_
