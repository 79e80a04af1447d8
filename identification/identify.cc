#include "identification/identify.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "identification/demod.h"
#include "identification/inductance.h"
#include "physics/speed.h"

namespace fluxcal::ident {
namespace {

using Complex = std::complex<double>;
constexpr double kTwoPi = 2.0 * std::numbers::pi;
// The relative standard error of Ldd or Lqq beyond which a point is
// flagged low_snr (its 2-sigma band wider than 1 %).
constexpr double kLowPrecisionRelStd = 0.005;
// The share of the smaller inductance beyond which the paper method's
// neglect of Ldq is flagged (ldq_neglected).
constexpr double kLdqNeglectedShare = 0.01;
// The dead-time sidebands' share of |I0| beyond which a rotating point is
// flagged dead_time_sidebands (PhasorEstimate::dead_time_sideband_ratio):
// the gate's mean, of about the sidebands' size, lies on I0 and I1 and
// biases the inductances by about as much or more (I1 is a fraction of
// I0). Measured (docs/identification.md, Sec. 6), the largest sideband per
// rotating point: the clean public sets 0.05-0.8 %, the twin's trait
// machines 0.01-0.94 % and with a 1 us dead time 1.6-9.1 %, the public
// dead-time sets 0.96-8.9 %.
constexpr double kDeadTimeSidebandShare = 0.01;

}  // namespace

absl::StatusOr<Method> ParseMethod(const std::string& name) {
  if (name == "paper") return Method::kPaper;
  if (name == "lsq") return Method::kLsq;
  return absl::InvalidArgumentError(
      absl::StrCat("flag --method: expected 'paper' or 'lsq', got '", name, "'"));
}

const char* MethodName(Method m) { return m == Method::kPaper ? "paper" : "lsq"; }

absl::StatusOr<HfPointResult> IdentifyPoint(const io::RecordingSet& set, size_t point,
                                            const IdentifyOptions& options) {
  const io::Manifest& m = set.manifest;
  if (point >= m.points.size() || point >= set.waveforms.size()) {
    return absl::OutOfRangeError(absl::StrCat("point index ", point, " out of range"));
  }
  const io::PointSpec& spec = m.points[point];
  const std::string where = absl::StrCat(set.root_dir, "/", spec.file);
  if (!m.injection) {
    return absl::InvalidArgumentError(absl::StrCat(where, ": field 'injection': missing in manifest"));
  }
  const io::Waveform& w = set.waveforms[point];
  const double fs = m.drive.f_sample_hz;
  const double fi = m.injection->frequency_hz;
  const double f_pwm = m.drive.f_pwm_hz.value_or(fs);
  const double wi = kTwoPi * fi;
  PhaseSamples s{w.ia_a.data(), w.ib_a.data(), w.ic_a.data(), w.theta_e_rad.data(), w.size(), fs, fi};

  auto prefix = [&](const absl::Status& st) {
    return absl::Status(st.code(), absl::StrCat(where, ": point '", spec.id, "': ", st.message()));
  };
  // The LSQ fit always runs: it supplies the quality metrics and the
  // fundamental current for both methods.
  auto lsq = LsqDemodulate(s);
  if (!lsq.ok()) return prefix(lsq.status());
  auto volt = FitCommandVoltage(w.ualpha_ref_v.data(), w.ubeta_ref_v.data(), w.theta_e_rad.data(),
                                w.size(), fs, fi);
  if (!volt.ok()) return prefix(volt.status());
  const Complex v_eff = EffectiveVoltage(volt->v_cmd_v, wi, f_pwm);
  // The negative sequence's frequency in the stationary frame: w_2 = 2 w_e - w_i.
  const Complex v_neg_eff = EffectiveVoltage(volt->v_neg_cmd_v, 2.0 * lsq->w_e_rad_s - wi, f_pwm);
  // Nothing to invert without an injection and a response above the noise.
  if (std::abs(volt->v_cmd_v) < 1e-3 * m.injection->amplitude_v ||
      std::norm(lsq->i0_a) <= 4.0 * lsq->var_i0_a2 || std::abs(lsq->i0_a) < 1e-9) {
    return prefix(absl::FailedPreconditionError(absl::StrFormat(
        "no HF response to invert (|V| = %.3g V, |I0| = %.3g A)", std::abs(volt->v_cmd_v), std::abs(lsq->i0_a))));
  }

  HfPointResult r;
  r.point = spec.id;
  r.id_a = lsq->fundamental_dq_a.real();
  r.iq_a = lsq->fundamental_dq_a.imag();
  r.speed_rpm = physics::ElectricalRadSToRpm(lsq->w_e_rad_s, m.motor.pole_pairs);
  r.temperature_c = spec.temperature_c.value_or(25.0);
  r.v_eff_v = v_eff;
  r.v_neg_eff_v = v_neg_eff;
  r.periods_used = lsq->periods_used;
  r.residual_rms_a = lsq->residual_rms_a;

  PhasorEstimate est = *lsq;
  bool ldq_neglected = false;   // paper method only (below)
  if (options.method == Method::kPaper) {
    auto paper = PaperDemodulate(s, options.compensate_delay_filters);
    if (!paper.ok()) return prefix(paper.status());
    est = *paper;
    r.periods_used = paper->periods_used;
    auto L = PaperInductance(est.i0_a, est.i1_a, std::abs(v_eff), wi,
                             {est.var_i0_a2, est.var_i1_a2, {}});
    if (!L.ok()) return prefix(L.status());
    r.ld_h = L->ldd_h; r.lq_h = L->lqq_h;
    r.ld_h_std = L->ldd_h_std; r.lq_h_std = L->lqq_h_std;
    r.has_ldq = false;
    // The paper's eq. (8) takes |I1| for (Ldd - Lqq)/2, i.e. it assumes
    // Ldq = 0: with D = (Ldd - Lqq)/2 + j Ldq its values are S +- |D|, each
    // off by |D| - |Re D|. The LSQ solve of the same point measures Ldq;
    // where that bias exceeds kLdqNeglectedShare of the smaller inductance
    // the point says so (machines with cross saturation: 15-43 % on the
    // measured-magnetics benches of issue 27, a property of the method).
    auto full = InductanceFromPhasors(lsq->i0_a, lsq->i1_a, v_eff, v_neg_eff, wi, lsq->w_e_rad_s,
                                      {lsq->var_i0_a2, lsq->var_i1_a2, lsq->cov_i0_i1_a2});
    if (full.ok()) {
      const double half_diff = 0.5 * (full->ldd_h - full->lqq_h);
      const double bias = std::hypot(half_diff, full->ldq_h) - std::abs(half_diff);
      const double smaller = std::min(std::abs(full->ldd_h), std::abs(full->lqq_h));
      if (smaller > 0 && bias > kLdqNeglectedShare * smaller && std::abs(full->ldq_h) > 3 * full->ldq_h_std) {
        ldq_neglected = true;
      }
    }
  } else {
    auto L = InductanceFromPhasors(est.i0_a, est.i1_a, v_eff, v_neg_eff, wi, lsq->w_e_rad_s,
                                   {est.var_i0_a2, est.var_i1_a2, est.cov_i0_i1_a2});
    if (!L.ok()) return prefix(L.status());
    r.ld_h = L->ldd_h; r.lq_h = L->lqq_h; r.ldq_h = L->ldq_h; r.r_hf_ohm = L->r_hf_ohm;
    r.ld_h_std = L->ldd_h_std; r.lq_h_std = L->lqq_h_std;
    r.ldq_h_std = L->ldq_h_std; r.r_hf_ohm_std = L->r_hf_ohm_std;
    r.has_ldq = true;
  }
  r.i0_a = est.i0_a;
  r.i1_a = est.i1_a;

  // Quality.
  const double i0_mag = std::abs(lsq->i0_a);
  const double noise_power = lsq->residual_rms_a * lsq->residual_rms_a;
  r.snr_db = noise_power > 0 ? 10.0 * std::log10(i0_mag * i0_mag / noise_power) : 300.0;
  r.harmonic_ratio = lsq->harmonic_ratio;
  // Phase currents lingering near zero (the paper's Sec. 3.3): a phase whose
  // fundamental is smaller than the HF ripple crosses zero every injection
  // period, where dead time distorts the applied voltage.
  const double ripple = i0_mag + std::abs(lsq->i1_a);
  size_t near_zero = 0;
  double max_abs = 0;
  for (size_t k = 0; k < w.size(); ++k) {
    const double a = std::abs(w.ia_a[k]), b = std::abs(w.ib_a[k]), c = std::abs(w.ic_a[k]);
    if (std::min({a, b, c}) < 0.5 * ripple) ++near_zero;
    max_abs = std::max({max_abs, a, b, c});
  }
  r.near_zero_fraction = static_cast<double>(near_zero) / static_cast<double>(w.size());
  // Clipping: the command's magnitude at the linear modulation limit, or a
  // current sample pinned at its extreme for several consecutive samples.
  const double udc = m.drive.udc_v.value_or(0.0);
  if (udc > 0) {
    size_t at_limit = 0;
    for (size_t k = 0; k < w.size(); ++k) {
      const double u = std::hypot(w.ualpha_ref_v[k], w.ubeta_ref_v[k]);
      const double ud = std::isnan(w.udc_v[k]) ? udc : w.udc_v[k];
      if (u >= 0.999 * ud / std::sqrt(3.0)) ++at_limit;
    }
    if (at_limit > 0) r.clipped = true;
  }
  size_t pinned = 0, run = 0;
  for (size_t k = 1; k < w.size(); ++k) {
    const bool same = max_abs > 0 && (std::abs(w.ia_a[k]) == max_abs || std::abs(w.ib_a[k]) == max_abs ||
                                      std::abs(w.ic_a[k]) == max_abs) &&
                      (w.ia_a[k] == w.ia_a[k - 1] || w.ib_a[k] == w.ib_a[k - 1] || w.ic_a[k] == w.ic_a[k - 1]);
    run = same ? run + 1 : 0;
    pinned = std::max(pinned, run);
  }
  if (pinned >= 3) r.clipped = true;

  if (r.periods_used < 10) r.flags.push_back("too_few_periods");
  if (r.clipped) r.flags.push_back("clipping");
  // At speed, where the sidebands are resolved, they measure what the
  // zero crossings do to this point; the fraction near zero is only the
  // risk (every rotating point crosses zero, and it flagged all of them).
  r.dead_time_sideband_ratio = lsq->dead_time_sideband_ratio;
  if (std::isfinite(r.dead_time_sideband_ratio)) {
    if (r.dead_time_sideband_ratio > kDeadTimeSidebandShare) r.flags.push_back("dead_time_sidebands");
  } else if (r.near_zero_fraction > kNearZeroFraction) {
    r.flags.push_back("phase_current_near_zero");
  }
  // low_snr: the estimate's precision, not the per-sample ratio. The
  // standard error of Ldd or Lqq above kLowPrecisionRelStd of its value
  // (a 2-sigma band wider than 1 %). A per-sample SNR below 20 dB used to
  // flag rotating points whose 10^3-10^4 samples pinned the inductance to
  // 0.1 % (the public bench sets on a measured machine: 23-32 dB, errors
  // 0.03-0.06 %), while points a dead time spoils carry standard errors
  // of 0.5-2.2 % there (docs/identification.md, Sec. 6).
  const double rel_std = std::max(r.ld_h_std / std::abs(r.ld_h), r.lq_h_std / std::abs(r.lq_h));
  if (!(rel_std <= kLowPrecisionRelStd)) r.flags.push_back("low_snr");
  if (r.harmonic_ratio > 1e-3) r.flags.push_back("harmonic_distortion");
  if (ldq_neglected) r.flags.push_back("ldq_neglected");
  r.reliable = r.flags.empty();
  return r;
}

absl::StatusOr<std::vector<HfPointResult>> IdentifySet(const io::RecordingSet& set,
                                                       const IdentifyOptions& options) {
  std::vector<HfPointResult> out;
  out.reserve(set.waveforms.size());
  for (size_t k = 0; k < set.waveforms.size(); ++k) {
    if (options.progress) options.progress(k, set.waveforms.size());
    if (options.cancelled && options.cancelled()) {
      return absl::CancelledError(absl::StrCat("identification: stopped before point ", k, " of ",
                                               set.waveforms.size(), " (cancelled by the caller)"));
    }
    auto r = IdentifyPoint(set, k, options);
    if (r.ok()) {
      out.push_back(std::move(*r));
      continue;
    }
    // A point whose HF response cannot be inverted (no response, |I1| >=
    // |I0| for eq. (8), 2 w_e = w_i) is reported, not fatal to the set: its
    // values are NaN, it is unreliable and says why. Malformed input stays
    // an error.
    if (r.status().code() != absl::StatusCode::kFailedPrecondition) return r.status();
    HfPointResult bad;
    bad.point = set.manifest.points[k].id;
    const double nan = std::numeric_limits<double>::quiet_NaN();
    bad.id_a = bad.iq_a = bad.ld_h = bad.lq_h = bad.ldq_h = bad.r_hf_ohm = nan;
    bad.ld_h_std = bad.lq_h_std = bad.ldq_h_std = bad.r_hf_ohm_std = nan;
    bad.speed_rpm = set.manifest.points[k].speed_rpm;
    bad.reliable = false;
    bad.flags.push_back("identification_failed");
    bad.failure = std::string(r.status().message());
    out.push_back(std::move(bad));
  }
  return out;
}

}  // namespace fluxcal::ident
