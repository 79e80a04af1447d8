// Mechanical orders at speed (waveform.cc locates the rest): physics that
// follows the rotor's mechanical angle -- a weak magnet, an eccentric rotor
// or encoder, a load pulsing with the shaft -- puts lines at rotor-frame
// frequencies o f_mech, o = +-1 (in the stator f_e (1 + o / p): the
// classic fault sidebands f_s (1 +- k / p), e.g. Rosero et al., "Study on
// the permanent magnet demagnetization fault in PMSMs", IEEE IECON 2006).
// On a 0.1 s record below ~1500 rpm they lie within the bins around the
// fundamental that the current spectrum leaves to the nuisance, and the
// open-loop replay's settling fills those bins, so the current residual
// cannot show them. The bench's current controller holds the current and
// puts what it rejects into its voltage command: the recorded command in
// the rotor frame,
//   u_dq(t) = (u_alpha + j u_beta)(t) e^{-j theta(t)},
// is regressed on the nuisance -- a constant, ramp and square in time (the
// operating point and its drift), the injection's rotor-frame harmonics
// e^{j m (w_i t - theta)}, m = -5..5, the electrical harmonics
// e^{j k theta}, k = +-1..+-12 (inverter and spatial harmonics), their
// intermodulation a f_i + b f_e near the tested band -- and on
// e^{j o theta / p} (theta the unwrapped recorded electrical angle: theta / p
// is the mechanical angle up to the pole-pair sector, a constant phase the
// complex coefficient absorbs), with six half-integer orders beside them as
// probes of the noise there. The noise: the regression residual's
// variance, s2 = |r|^2 / (n - k) (white; anything deterministic left in it
// only makes the test more cautious). With c ~ CN(c_true, s2 (M^H M)^-1),
// z^2 = |c_o|^2 / C_oo is a line's power over its noise as the spectrum's
// bins are judged (p = e^{-z^2}). Where the record spans too little of a
// revolution to tell an order from the drift, C_oo grows and nothing is
// claimed. No catalogue effect and no magnetics of the machine's own
// (functions of the electrical angle and the currents) put anything at a
// mechanical order.
#include <algorithm>
#include <cmath>
#include <cstdlib>

#include "diagnosis/internal.h"

namespace fluxcal::diag::detail {
namespace {
constexpr double kMinRevolutions = 1.5;
constexpr double kMaxInflation = 10.0;
// The regression holds ~50 complex columns of the record: at most this many
// samples of it (2 s at 10 kHz, tens of revolutions at any speed the test
// applies to), so a long record costs bounded memory and time.
constexpr size_t kMaxSamples = 20000;
}  // namespace

std::vector<WaveformLine> MechanicalOrderVoltageLines(const io::Waveform& w, double f_sample_hz, double f_i_hz,
                                                      int pole_pairs, double f_e_hz, double line_z2) {
  std::vector<WaveformLine> out;
  const size_t n = std::min(w.size(), kMaxSamples);
  if (pole_pairs < 2 || !std::isfinite(f_e_hz) || f_e_hz == 0.0 || !(f_sample_hz > 0) || n < 256 ||
      w.ualpha_ref_v.size() != w.size() || w.ubeta_ref_v.size() != w.size() || w.theta_e_rad.size() != w.size()) {
    return out;
  }
  const double p = pole_pairs, w_i = 2 * kPi * f_i_hz;
  std::vector<double> th(n);
  th[0] = w.theta_e_rad[0];
  for (size_t k = 1; k < n; ++k) th[k] = th[k - 1] + std::remainder(w.theta_e_rad[k] - w.theta_e_rad[k - 1], 2 * kPi);
  // The record must span 1.5 revolutions: over less, a mechanical order, the
  // probes beside it and the drift are too alike to be told apart.
  if (std::abs(th[n - 1] - th[0]) / (2 * kPi * p) < kMinRevolutions) return out;
  Eigen::VectorXcd u(n);
  for (size_t k = 0; k < n; ++k) u(k) = Complex(w.ualpha_ref_v[k], w.ubeta_ref_v[k]) * std::polar(1.0, -th[k]);
  std::vector<int> orders;
  for (int o : {-1, 1}) orders.push_back(o);
  std::vector<Eigen::VectorXcd> cols;
  auto tau = [&](size_t k) { return 2.0 * static_cast<double>(k) / static_cast<double>(n - 1) - 1.0; };
  for (int pw = 0; pw <= 2; ++pw) {
    Eigen::VectorXcd c(n);
    for (size_t k = 0; k < n; ++k) c(k) = std::pow(tau(k), pw);
    cols.push_back(c);
  }
  if (w_i > 0) {
    for (int m = -5; m <= 5; ++m) {
      if (m == 0) continue;
      Eigen::VectorXcd c(n);
      for (size_t k = 0; k < n; ++k) c(k) = std::polar(1.0, m * (w_i * static_cast<double>(k) / f_sample_hz - th[k]));
      cols.push_back(c);
    }
  }
  for (int e = -12; e <= 12; ++e) {
    if (e == 0) continue;
    Eigen::VectorXcd c(n);
    for (size_t k = 0; k < n; ++k) c(k) = std::polar(1.0, e * th[k]);
    cols.push_back(c);
  }
  // Intermodulation of the injection and the fundamental (the inverter's
  // dead time and the saturation are nonlinear in the sum of both
  // currents): rotor-frame lines at a f_i + b f_e. Those in the band of
  // the tested orders and probes are nuisance too. Where f_i / f_e is
  // rational one can coincide with a mechanical order -- 500 Hz and
  // 66.7 Hz put 500 - 7 x 66.7 = 33.3 Hz = 2 f_mech at 4 pole pairs -- and
  // that order's variance inflation then takes it out of the test: the
  // record cannot tell the two apart.
  // A term within one frequency bin (1 / record) of one already in the
  // nuisance is left to it: the two are alike over the record.
  const double record_s = static_cast<double>(n) / f_sample_hz;
  const double band_hz = std::abs(f_e_hz) / p + 2.0 / record_s;
  std::vector<double> in_nuisance = {0.0};
  for (int m = -5; m <= 5; ++m) in_nuisance.push_back(m * (f_i_hz - f_e_hz));
  for (int e = -12; e <= 12; ++e) in_nuisance.push_back(e * f_e_hz);
  if (w_i > 0) {
    for (int a = -4; a <= 4; ++a) {
      for (int b = -60; b <= 60 && a != 0; ++b) {
        const double f = a * f_i_hz + b * f_e_hz;
        if (std::abs(f) > band_hz) continue;
        bool known = false;
        for (double g : in_nuisance) known |= std::abs(f - g) < 1.0 / record_s;
        if (known) continue;
        in_nuisance.push_back(f);
        Eigen::VectorXcd c(n);
        for (size_t k = 0; k < n; ++k) c(k) = std::polar(1.0, a * w_i * static_cast<double>(k) / f_sample_hz + b * th[k]);
        cols.push_back(c);
      }
    }
  }
  const size_t first_order = cols.size();
  for (int o : orders) {
    Eigen::VectorXcd c(n);
    for (size_t k = 0; k < n; ++k) c(k) = std::polar(1.0, o * th[k] / p);
    cols.push_back(c);
  }
  // Probes: half-integer mechanical orders, periodic in nothing physical,
  // beside the tested ones. Fitted jointly (so a true line does not leak
  // into them), their coefficients measure the noise at these low
  // rotor-frame frequencies, where the controller's integrators colour it.
  const size_t first_probe = cols.size();
  constexpr double probe_orders[] = {-3.5, -2.5, -1.5, 1.5, 2.5, 3.5};
  for (double o : probe_orders) {
    Eigen::VectorXcd c(n);
    for (size_t k = 0; k < n; ++k) c(k) = std::polar(1.0, o * th[k] / p);
    cols.push_back(c);
  }
  Eigen::MatrixXcd M(n, cols.size());
  for (size_t j = 0; j < cols.size(); ++j) M.col(static_cast<Eigen::Index>(j)) = cols[j];
  const Eigen::ColPivHouseholderQR<Eigen::MatrixXcd> qr(M);
  if (qr.rank() < M.cols()) return out;
  const Eigen::VectorXcd c = qr.solve(u);
  const Eigen::VectorXcd r = u - M * c;
  const double s2 = r.squaredNorm() / static_cast<double>(n - cols.size());
  const Eigen::MatrixXcd MtM = M.adjoint() * M;
  const Eigen::MatrixXcd cov = MtM.ldlt().solve(Eigen::MatrixXcd::Identity(M.cols(), M.cols()));
  // |c|^2 / var of white noise is exponential with mean 1 (a complex
  // coefficient: chi^2_2 / 2): the median of such ratios over ln 2 (over
  // 5/6 for three of them, the mean of the middle of three exponentials) is
  // the factor by which the noise there exceeds the white estimate. The
  // noise is coloured, rising towards zero frequency (the controller's
  // integrators), and not alike on both sides: in the rotor frame the
  // positive frequencies carry the current controller's reaction (on the
  // second motor's plan at 1500 rpm the probes at +1.5..+3.5 orders read
  // 4-40 times the white estimate, those at -1.5..-3.5 under 1). Each order
  // is judged by the larger of the factor of all six probes and that of
  // the three on its own side: the six alone mixed the quiet side in and
  // read lines at +1 of 5.7 and 7.7 sigma on sets without any mechanical
  // effect (scripts/diagnosis-probe.py, cs_12u_s22 and mt_1111_s21); the
  // own side alone missed the rise towards zero on the quiet side (lines at
  // -1 of 5.3-5.8 sigma on clean matrix sets).
  auto colour_of = [&](int sign) {
    std::vector<double> ratio;
    for (size_t j = first_probe; j < cols.size(); ++j) {
      if (sign != 0 && (probe_orders[j - first_probe] > 0) != (sign > 0)) continue;
      const Eigen::Index col = static_cast<Eigen::Index>(j);
      const double var = s2 * cov(col, col).real();
      if (var > 0) ratio.push_back(std::norm(c(col)) / var);
    }
    if (ratio.empty()) return 1.0;
    std::nth_element(ratio.begin(), ratio.begin() + ratio.size() / 2, ratio.end());
    const double median_of_unit = ratio.size() == 3 ? 5.0 / 6.0 : std::log(2.0);
    return std::max(1.0, ratio[ratio.size() / 2] / median_of_unit);
  };
  const double colour_all = colour_of(0);
  for (size_t j = 0; j < orders.size(); ++j) {
    const Eigen::Index col = static_cast<Eigen::Index>(first_order + j);
    // Variance inflation n C_oo (1 for a regressor orthogonal to the rest,
    // each of unit modulus): above kMaxInflation the order is mostly the
    // other regressors' and its estimate says little.
    if (!(static_cast<double>(n) * cov(col, col).real() <= kMaxInflation)) continue;
    const double var = std::max(colour_all, colour_of(orders[j])) * s2 * cov(col, col).real();
    if (!(var > 0)) continue;
    const double z2 = std::norm(c(col)) / var;
    if (!(z2 >= line_z2)) continue;   // NaN too: a line is only what the numbers show

    WaveformLine l;
    l.channel = "phase_voltage";
    l.freq_hz = f_e_hz * (1.0 + orders[j] / p);
    l.amp_a = std::abs(c(col));
    l.z2 = z2;
    l.kind = "mechanical_order";
    l.order = pole_pairs + orders[j];
    out.push_back(l);
  }
  return out;
}

}  // namespace fluxcal::diag::detail
