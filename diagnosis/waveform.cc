// The waveform-level locator (docs/diagnosis.md, "The waveforms"): every
// recorded test replayed through the twin with the model (the set's own
// calibration and the effects found so far), the recorded phase currents
// compared sample by sample, and what the model does not reproduce
// located as lines in the residual's spectrum.
//
// Per point, the residual e = recorded - simulated (alpha-beta, complex;
// and the zero sequence (ia + ib + ic) / 3, which a star winding cannot
// carry, so whatever shows there is the sensors') is first freed of what
// the summarised observables already judge and of the machine's own
// nonlinearity over the HF excursion ("nuisance", least squares):
//   - the fundamental and its slow drift: e^{j theta} (1, tau, tau^2) and
//     e^{-j theta} (1, tau), a constant and a ramp (tau = time over the
//     record, -1..1): the held or steady-state current the DC and
//     steady-state observables compare, and an open-loop replay's settling;
//   - the HF response and its harmonics in the rotor frame,
//     e^{j theta} e^{j m (w_i t - theta)}, m = -5..5 (m = 1 is the
//     positive sequence at w_i, m = -1 the negative one at 2 w_e - w_i):
//     the HF phasors are what hf_current compares, and their harmonics are
//     the saturation curve's own bending over the HF ellipse (a measured
//     PM-SyRM at its knee puts 20-30 mA at 4 w_i, 0.1 % of its HF current;
//     no smooth calibration reproduces that curvature exactly).
// What remains is tested against the noise of the recording itself: the
// residual's Hann-windowed spectrum, the noise per bin the median of the
// bins away from the nuisance lines (an exponential distribution's median
// is ln 2 times its mean). A bin that is a local maximum with power z^2 =
// |R|^2 / sigma^2 >= kLineZ2 is a line (p = e^{-z^2} per bin: 5.6e-7, a
// one-sided 5 sigma). Lines are named by what they are multiples of:
// injection sidebands (rotor frame m (w_i - w_e) + j w_e), harmonics of the
// electrical frequency, mechanical orders (electrical / pole pairs),
// harmonics of the injection at standstill, lines at one fixed frequency at
// several points (interference), and lines nothing explains.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <complex>
#include <limits>
#include <map>
#include <numeric>
#include <tuple>

#include <unsupported/Eigen/FFT>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "diagnosis/internal.h"
#include "simulation/frames.h"

namespace fluxcal::diag::detail {
namespace {

// Power of a bin over the noise per bin at which a local maximum is a line:
// e^{-14.4} = 5.6e-7, a one-sided Gaussian 5 sigma.
constexpr double kLineZ2 = 14.4;
// Harmonic orders of the rotor-frame HF response taken as the machine's own
// (nuisance).
constexpr int kHfHarmonics = 5;

struct Label {
  std::string kind;   // "" when nothing names it
  int order = 0;      // harmonic number, mechanical order or sideband order
  int m = 0;          // injection_sideband: the HF harmonic it sits beside
};

// What a line at f_hz is a multiple of, at a point turning at f_e_hz
// (signed electrical frequency; 0 at standstill) with injection f_i_hz.
Label Name(double f, double f_e, double f_i, int pole_pairs, double tol) {
  Label l;
  const bool turning = std::abs(f_e) >= 2 * tol;
  if (!turning) {
    const int m = static_cast<int>(std::lround(f / f_i));
    if (m != 0 && std::abs(f - m * f_i) <= tol) return {"injection_harmonic", m, m};
    return l;
  }
  // Rotor-frame sidebands of the HF response and its harmonics:
  // f = f_e + m (f_i - f_e) + j f_e.
  for (int m = -kHfHarmonics - 1; m <= kHfHarmonics + 1; ++m) {
    if (m == 0) continue;
    const double base = f_e + m * (f_i - f_e);
    const int j = static_cast<int>(std::lround((f - base) / f_e));
    if (std::abs(j) <= 12 && std::abs(f - base - j * f_e) <= tol) {
      if (j == 0) return {"injection_harmonic", m, m};
      return {"injection_sideband", j, m};
    }
  }
  const int k = static_cast<int>(std::lround(f / f_e));
  if (k != 0 && std::abs(k) <= 31 && std::abs(f - k * f_e) <= tol) return {"electrical_harmonic", k, 0};
  const int km = static_cast<int>(std::lround(pole_pairs * f / f_e));
  if (km % pole_pairs != 0 && std::abs(km) <= 4 * pole_pairs && std::abs(f - km * f_e / pole_pairs) <= tol) {
    return {"mechanical_order", km, 0};
  }
  return l;
}

}  // namespace

// The model's own line at bin b (internal.h): as uncertain as its size
// (kModelLineAccuracy, internal.h) and in its place by a bin: the largest
// of the bin and its neighbours (the Hann window's main lobe). A model whose lines are a
// dense comb (a dead time's sidebands of the injection at 6 k f_e, 10-80
// mA at 200 rpm) can null one bin between two of its lines by
// coincidence, and a residual of the comb's size read there as a line no
// model explains (a 35 mA line, 6.8 sigma, beside larger model lines;
// the probe's `pair_udc_dt_s93`).
double ModelLineSize(const std::vector<Complex>& sim, size_t b) {
  const size_t n = sim.size();
  return kModelLineAccuracy *
         std::max({std::abs(sim[(b + n - 1) % n]), std::abs(sim[b]), std::abs(sim[(b + 1) % n])});
}

namespace {

// The zero sequence the model's own sensor gains make of what the replay
// misses in the phase currents, taken out of the zero-sequence residual
// `e0` (per sample k, sample k + 1 of the records). The readings are
// x_j = g_j i_j + o_j with i_a + i_b + i_c = 0, so the recorded zero
// sequence is 3 z = (g_a - g_c) i_a + (g_b - g_c) i_b + sum o, and the
// replay's the same with its own gains and currents. With the gains right,
// 3 (z_rec - z_rep) = (g_a - g_c) d_a + (g_b - g_c) d_b + const to first
// order, d_j = x_j,rec - x_j,rep the phase residual: a found 2 % gain
// carries 2 % of whatever the replay misses in phase a into the zero
// sequence, where the noise is all it is judged against (the phase
// currents take what the model puts at a line as that line's uncertainty,
// ModelLineSize; a deep-saturation machine's +-48 A orbit at speed left
// 9 sigma sidebands there). The gain differences are read off the replay
// itself: its zero sequence regressed on its phase readings a and b and a
// constant gives (g_a - g_c) / g_a and (g_b - g_c) / g_b, zero when the
// model has no gain. Only this first-order term is taken: what the
// recorded zero sequence holds beyond the model's gains (a crosstalk
// between two sensors, an error in a gain) stays in the residual.
// Returns whether a term was taken.
bool ModelZeroSequenceGains(const io::Waveform& w, const sim::ReplayPoint& r, Eigen::VectorXd* e0) {
  const Eigen::Index n = e0->size();
  Eigen::MatrixXd X(n, 3);
  Eigen::VectorXd z(n);
  for (Eigen::Index k = 0; k < n; ++k) {
    const size_t s = static_cast<size_t>(k) + 1;
    X(k, 0) = r.ia_a[s];
    X(k, 1) = r.ib_a[s];
    X(k, 2) = 1.0;
    z(k) = r.ia_a[s] + r.ib_a[s] + r.ic_a[s];
  }
  const Eigen::Vector3d c = X.colPivHouseholderQr().solve(z);
  if (!c.allFinite() || std::max(std::abs(c(0)), std::abs(c(1))) < 1e-9) return false;
  for (Eigen::Index k = 0; k < n; ++k) {
    const size_t s = static_cast<size_t>(k) + 1;
    (*e0)(k) -= (c(0) * (w.ia_a[s] - r.ia_a[s]) + c(1) * (w.ib_a[s] - r.ib_a[s])) / 3.0;
  }
  return true;
}
}  // namespace

std::vector<WaveformPoint> AnalyseWaveforms(const io::RecordingSet& set, const std::vector<sim::ReplayPoint>& replay,
                                            int pole_pairs) {
  std::vector<WaveformPoint> out;
  const auto& mf = set.manifest;
  const double fs = mf.drive.f_sample_hz;
  const double f_i = mf.injection ? mf.injection->frequency_hz : 0.0;
  const double w_i = 2 * kPi * f_i;
  Eigen::FFT<double> fft;
  for (size_t p = 0; p < replay.size() && p < set.waveforms.size(); ++p) {
    const auto& w = set.waveforms[p];
    const auto& r = replay[p];
    // Sample 0 is not simulated (ReplayOpenLoop).
    const size_t n = w.size() > 1 ? w.size() - 1 : 0;
    if (n < 64 || r.ia_a.size() != w.size()) continue;
    if (ReplayRanAway(w, r)) continue;
    WaveformPoint wp;
    wp.point = mf.points[p].id;
    wp.index = p;
    wp.speed_rpm = mf.points[p].speed_rpm;
    wp.df_hz = fs / static_cast<double>(n);
    // Unwrapped recorded angle; the electrical frequency from its line.
    std::vector<double> th(n);
    double unwrapped = w.theta_e_rad[1];
    for (size_t k = 0; k < n; ++k) {
      if (k > 0) unwrapped += std::remainder(w.theta_e_rad[k + 1] - w.theta_e_rad[k], 2 * kPi);
      th[k] = unwrapped;
    }
    wp.f_e_hz = (th[n - 1] - th[0]) / (static_cast<double>(n - 1) / fs) / (2 * kPi);
    if (std::abs(wp.speed_rpm) == 0.0) wp.f_e_hz = 0.0;
    Eigen::VectorXcd e(n), sim_i(n);
    Eigen::VectorXd e0(n);
    Complex mean_i = 0;
    for (size_t k = 0; k < n; ++k) {
      const size_t s = k + 1;
      const sim::AlphaBeta rec = sim::Clarke(w.ia_a[s], w.ib_a[s], w.ic_a[s]);
      const sim::AlphaBeta sim_ab = sim::Clarke(r.ia_a[s], r.ib_a[s], r.ic_a[s]);
      e(k) = Complex(rec.alpha - sim_ab.alpha, rec.beta - sim_ab.beta);
      sim_i(k) = Complex(sim_ab.alpha, sim_ab.beta);
      e0(k) = (w.ia_a[s] + w.ib_a[s] + w.ic_a[s] - r.ia_a[s] - r.ib_a[s] - r.ic_a[s]) / 3.0;
      mean_i += Complex(rec.alpha, rec.beta) * std::polar(1.0, -th[k]);
    }
    mean_i /= static_cast<double>(n);
    wp.id_a = mean_i.real();
    wp.iq_a = mean_i.imag();
    // Nuisance regressors (file comment).
    std::vector<Eigen::VectorXcd> basis;
    std::vector<double> nuisance_hz = {0.0};
    auto tau = [&](size_t k) { return 2.0 * static_cast<double>(k) / static_cast<double>(n - 1) - 1.0; };
    {
      Eigen::VectorXcd one(n), ramp(n);
      for (size_t k = 0; k < n; ++k) { one(k) = 1.0; ramp(k) = tau(k); }
      basis.push_back(one);
      basis.push_back(ramp);
    }
    for (int pw = 0; pw <= 2; ++pw) {
      Eigen::VectorXcd b(n);
      for (size_t k = 0; k < n; ++k) b(k) = std::polar(std::pow(tau(k), pw), th[k]);
      basis.push_back(b);
      if (pw < 2) {
        for (size_t k = 0; k < n; ++k) b(k) = std::polar(std::pow(tau(k), pw), -th[k]);
        basis.push_back(b);
      }
    }
    nuisance_hz.push_back(wp.f_e_hz);
    nuisance_hz.push_back(-wp.f_e_hz);
    // The HF response's rotor-frame harmonics m = -M..M, M = kHfHarmonics
    // and beyond while the series goes on: where the HF current's ellipse
    // reaches across a knee (an orbit of a third of the operating current
    // on a strongly cross-saturated machine) the machine's own harmonics
    // continue past order 5 at sizes no smooth calibration reproduces,
    // and are as much its magnetics as orders 2..5. Order M + 1 is taken
    // as well while the residual's order M or M - 1 (either sign) stands
    // above the noise as a line would (kLineZ2, against the coefficient's
    // variance sigma^2 / n, sigma^2 from the residual's median power), up
    // to the order below Nyquist. Two orders, not one: about a point where
    // the curve bends symmetrically only odd orders appear (the negative-
    // slope machine's own dip at zero current: +-7, +-9), and elsewhere one
    // order can pass near zero between larger neighbours (a deep-
    // saturation machine's order 5 under the line threshold at a locked
    // point where order 6 stood at 8.7 sigma). A line at an order the
    // series does not lead to is still located.
    std::map<int, size_t> hf_column;   // order m -> its column in the basis
    auto add_hf = [&](int m) {
      hf_column[m] = basis.size();
      Eigen::VectorXcd b(n);
      for (size_t k = 0; k < n; ++k) {
        const double t = static_cast<double>(k + 1) / fs;
        b(k) = std::polar(1.0, th[k] + m * (w_i * t - th[k]));
      }
      basis.push_back(b);
      nuisance_hz.push_back(wp.f_e_hz + m * (f_i - wp.f_e_hz));
    };
    int hf_order = 0;
    if (w_i > 0) {
      for (int m = -kHfHarmonics; m <= kHfHarmonics; ++m) {
        if (m != 0) add_hf(m);
      }
      hf_order = kHfHarmonics;
    }
    const int hf_order_max = w_i > 0 ? static_cast<int>(std::floor(0.5 * fs / (f_i + std::abs(wp.f_e_hz)))) : 0;
    auto solve = [&](Eigen::VectorXcd* coef) {
      Eigen::MatrixXcd B(n, basis.size());
      for (size_t j = 0; j < basis.size(); ++j) B.col(j) = basis[j];
      *coef = B.colPivHouseholderQr().solve(e);
      return Eigen::VectorXcd(e - B * *coef);
    };
    Eigen::VectorXcd coef;
    Eigen::VectorXcd res = solve(&coef);
    while (hf_order > 0 && hf_order < hf_order_max) {
      std::vector<double> p(n);
      for (size_t k = 0; k < n; ++k) p[k] = std::norm(res(k));
      std::nth_element(p.begin(), p.begin() + n / 2, p.end());
      const double coef_var = p[n / 2] / std::log(2.0) / static_cast<double>(n);
      auto stands = [&](int m) {
        const double top = std::max(std::norm(coef(static_cast<long>(hf_column.at(-m)))),
                                    std::norm(coef(static_cast<long>(hf_column.at(m)))));
        return top / coef_var >= kLineZ2;
      };
      if (!stands(hf_order) && !stands(hf_order - 1)) break;
      ++hf_order;
      add_hf(-hf_order);
      add_hf(hf_order);
      res = solve(&coef);
    }
    // At speed, the bending orders |m| >= 2 of that series beside +-6 f_e:
    // in the rotor frame a sixth-order ripple of the operating point (a
    // dead time's, an inverter's) moves the orbit's centre, and the orbit's
    // own harmonics swing with it, m (w_i - w_e) + -6 w_e. They are the
    // bending's, as the orders are, and as uncertain: the replay puts them
    // there only as well as it follows the curvature over a +-48 A orbit
    // (a deep-saturation machine with a concealed 2 us dead time, found to
    // 0.3 %, at 500 rpm: its order -5 beside -6 f_e 50 mA off, 9.6 sigma,
    // where the replay is 2.4 A RMS off the recording). The orders +-1 are
    // left out: their sidebands are what the HF phasors and a dead time's
    // own signature are judged by.
    if (wp.f_e_hz != 0.0) {
      for (int m = -hf_order; m <= hf_order; ++m) {
        if (std::abs(m) < 2) continue;
        for (int j : {-6, 6}) {
          Eigen::VectorXcd b(n);
          for (size_t k = 0; k < n; ++k) {
            const double t = static_cast<double>(k + 1) / fs;
            b(k) = std::polar(1.0, th[k] + m * (w_i * t - th[k]) + j * th[k]);
          }
          basis.push_back(b);
          nuisance_hz.push_back(wp.f_e_hz + m * (f_i - wp.f_e_hz) + j * wp.f_e_hz);
        }
      }
      if (hf_order >= 2) res = solve(&coef);
    }
    ModelZeroSequenceGains(w, r, &e0);
    Eigen::VectorXd res0 = e0;
    {
      // The zero sequence: a constant and a ramp (sensor offsets).
      Eigen::MatrixXd B0(n, 2);
      for (size_t k = 0; k < n; ++k) { B0(k, 0) = 1.0; B0(k, 1) = tau(k); }
      res0 = e0 - B0 * B0.colPivHouseholderQr().solve(e0);
    }
    // Spectra (Hann window) and the noise per bin.
    std::vector<double> win(n);
    double wsum = 0;
    for (size_t k = 0; k < n; ++k) {
      win[k] = 0.5 * (1.0 - std::cos(2 * kPi * static_cast<double>(k) / static_cast<double>(n - 1)));
      wsum += win[k];
    }
    std::vector<Complex> xin(n), xout;
    std::vector<Complex> zin(n), zout, sin_(n), sout;
    for (size_t k = 0; k < n; ++k) {
      xin[k] = res(k) * win[k];
      zin[k] = Complex(res0(k) * win[k], 0.0);
      sin_[k] = sim_i(k) * win[k];
    }
    fft.fwd(xout, xin);
    fft.fwd(zout, zin);
    fft.fwd(sout, sin_);
    wp.spectrum_sim.assign(sout.begin(), sout.end());
    wp.freq_hz.resize(n);
    for (size_t b = 0; b < n; ++b) {
      const long kb = b <= n / 2 ? static_cast<long>(b) : static_cast<long>(b) - static_cast<long>(n);
      wp.freq_hz[b] = kb * wp.df_hz;
    }
    const double tol = 2.5 * wp.df_hz;
    std::vector<bool> quiet(n, true);   // bins away from the nuisance lines
    for (size_t b = 0; b < n; ++b) {
      for (double nf : nuisance_hz) {
        if (std::abs(wp.freq_hz[b] - nf) <= tol) quiet[b] = false;
      }
    }
    auto noise_of = [&](const std::vector<Complex>& spec, bool positive_only) {
      std::vector<double> pw;
      for (size_t b = 0; b < n; ++b) {
        if (!quiet[b] || (positive_only && wp.freq_hz[b] <= 0)) continue;
        pw.push_back(std::norm(spec[b]));
      }
      if (pw.empty()) return 1e-300;
      std::nth_element(pw.begin(), pw.begin() + pw.size() / 2, pw.end());
      return std::max(pw[pw.size() / 2] / std::log(2.0), 1e-300);
    };
    wp.sigma2_bin = noise_of(xout, false);
    wp.sigma2_bin_zero = noise_of(zout, true);
    // Per-sample noise of the residual: the windowed bin variance is
    // sigma^2 sum(w^2) for white noise of variance sigma^2.
    double w2 = 0;
    for (double x : win) w2 += x * x;
    wp.noise_a = std::sqrt(wp.sigma2_bin / w2 / 2.0);
    // The sensors' resolution: what the recorded currents' quantisation
    // puts in each bin (quantisation.cc).
    QuantisationSpectra(w, r, win, &wp);
    wp.spectrum.assign(xout.begin(), xout.end());
    wp.spectrum_zero.assign(zout.begin(), zout.end());
    wp.coherent_gain = wsum;
    wp.nuisance_hz = nuisance_hz;
    // Lines: local maxima above kLineZ2, away from the nuisance lines.
    auto detect = [&](const std::vector<Complex>& spec, double s2, const std::string& channel) {
      for (size_t b = 0; b < n; ++b) {
        if (!quiet[b]) continue;
        const bool real = channel != "phase_current";
        if (real && wp.freq_hz[b] <= 0) continue;
        const double model = channel == "phase_current" ? ModelLineSize(sout, b)
                             : channel == "rotor_angle" && !wp.spectrum_angle_model.empty()
                                 ? kModelLineAccuracy * std::abs(wp.spectrum_angle_model[b])
                                 : 0.0;
        const double quant = QuantisationPower(wp, channel, b);
        const double z2 = std::norm(spec[b]) / (s2 + model * model + quant);
        if (z2 < kLineZ2) continue;
        const double left = std::norm(spec[(b + n - 1) % n]), right = std::norm(spec[(b + 1) % n]);
        if (std::norm(spec[b]) < left || std::norm(spec[b]) < right) continue;
        WaveformLine l;
        l.channel = channel;
        l.freq_hz = wp.freq_hz[b];
        // Amplitude of a complex line A e^{j w t}: |X| / sum(w)
        // (the zero sequence is real: its cosine's amplitude is twice that).
        l.amp_a = std::abs(spec[b]) / wsum * (real ? 2.0 : 1.0);
        l.z2 = z2;
        if (channel == "phase_current") l.sim_amp_a = std::abs(sout[b]) / wsum;
        const Label nm = Name(l.freq_hz, wp.f_e_hz, f_i, pole_pairs, 1.5 * wp.df_hz);
        l.kind = nm.kind;
        l.order = nm.order;
        l.m = nm.m;
        wp.lines.push_back(l);
      }
    };
    detect(xout, wp.sigma2_bin, "phase_current");
    detect(zout, wp.sigma2_bin_zero, "zero_sequence_current");
    for (auto& l : MechanicalOrderVoltageLines(w, fs, f_i, pole_pairs, wp.f_e_hz, kLineZ2)) {
      wp.lines.push_back(std::move(l));
    }
    if (std::abs(wp.f_e_hz) > 0.0) {
      // The recorded angle at speed: the rotor turns at constant speed, so
      // what the reading does beyond its least-squares line is the sensor's
      // (its count quantisation, white; and any error that follows the
      // rotor's position, which no current residual shows: the currents
      // are measured in the stator).
      double sx = 0, sy = 0, sxx = 0, sxy = 0;
      for (size_t k = 0; k < n; ++k) {
        const double x = static_cast<double>(k);
        sx += x; sy += th[k]; sxx += x * x; sxy += x * th[k];
      }
      const double nn = static_cast<double>(n), den = nn * sxx - sx * sx;
      const double slope = den > 0 ? (nn * sxy - sx * sy) / den : 0.0, icpt = (sy - slope * sx) / nn;
      // The reading is quantised to counts: a line through them reads as a
      // sawtooth at the rate the counts slip against the samples, lines of
      // the sensor's resolution, not of the rotor. The count is the
      // smallest difference between the distinct increments of the reading
      // (m and m + 1 counts per sample); the sawtooth of an ideal line on
      // that grid is the channel's
      // model, judged as the model's own lines are (kModelLineAccuracy).
      std::vector<double> inc;
      for (size_t k = 1; k < n; ++k) inc.push_back(th[k] - th[k - 1]);
      std::sort(inc.begin(), inc.end());
      double count = 0;
      for (size_t k = 1; k < inc.size(); ++k) {
        const double d = inc[k] - inc[k - 1];
        if (d > 1e-5 && (count == 0 || d < count)) count = d;
      }
      if (count > 0) {
        // Refined over the whole record: every increment is a whole number
        // m of counts, count = sum(inc m) / sum(m^2) (least squares); the
        // file's decimals blur one difference, a thousand increments not.
        double sim_ = 0, smm = 0;
        for (size_t k = 1; k < n; ++k) {
          const double d = th[k] - th[k - 1];
          const double mk = std::round(d / count);
          sim_ += d * mk;
          smm += mk * mk;
        }
        if (smm > 0) count = sim_ / smm;
      }
      std::vector<double> line(n), quant(n, 0.0);
      for (size_t k = 0; k < n; ++k) line[k] = icpt + slope * static_cast<double>(k);
      // The model's own sensor error (a position-sensor harmonic found by
      // the diagnosis, ReplayPoint::angle_error_rad): the reading modelled
      // is the line plus it, then quantised.
      std::vector<double> err(n, 0.0);
      if (r.angle_error_rad.size() == w.size()) {
        for (size_t k = 0; k < n; ++k) err[k] = r.angle_error_rad[k + 1];
      }
      // The named error's second-harmonic part, refined on this record: its
      // amplitude and phase come from the currents (to ~10 %), while the
      // quantised reading moves a count wherever the error does, so a few
      // per cent off shifts transitions and leaves sawtooth lines the
      // effect does not cause. Least squares of the reading beyond its
      // line on sin / cos(2 theta); the refined harmonic replaces the
      // model's only when it is the same effect (amplitude within 30 %,
      // phase within 0.3 rad): an error the model does not name is never
      // fitted here.
      {
        double ss = 0, cc = 0, sc = 0, sr = 0, cr = 0, se = 0, ce = 0;
        for (size_t k = 0; k < n; ++k) {
          const double sk = std::sin(2 * line[k]), ck = std::cos(2 * line[k]), rk = th[k] - line[k];
          ss += sk * sk; cc += ck * ck; sc += sk * ck;
          sr += sk * rk; cr += ck * rk; se += sk * err[k]; ce += ck * err[k];
        }
        const double det = ss * cc - sc * sc;
        if (det > 0) {
          const Complex model((cc * se - sc * ce) / det, (ss * ce - sc * se) / det);
          const Complex data((cc * sr - sc * cr) / det, (ss * cr - sc * sr) / det);
          if (std::abs(model) > 0 && std::abs(std::abs(data) / std::abs(model) - 1.0) < 0.3 &&
              std::abs(std::arg(data / model)) < 0.3) {
            for (size_t k = 0; k < n; ++k) {
              const double sk = std::sin(2 * line[k]), ck = std::cos(2 * line[k]);
              err[k] += (data.real() - model.real()) * sk + (data.imag() - model.imag()) * ck;
            }
          }
        }
      }
      if (count > 0) {
        // The grid's zero: the readings lie on c + m count, so c is the
        // circular mean of the readings modulo a count. The line's own
        // offset (least squares through a quantised ramp is off by up to a
        // fraction of a count, and where the counts slip slowly -- 1.02
        // counts per sample at 150 rpm -- that fraction moves every
        // transition) is refined on a grid of 128 offsets within a count.
        Complex phasor = 0;
        for (size_t k = 0; k < n; ++k) phasor += std::polar(1.0, 2 * kPi * th[k] / count);
        const double c = count * std::arg(phasor) / (2 * kPi);
        double best = std::numeric_limits<double>::infinity(), best_shift = 0;
        for (int t = -64; t < 64; ++t) {
          const double shift = count * t / 128.0;
          double se = 0;
          for (size_t k = 0; k < n; ++k) {
            const double qk = std::round((line[k] + err[k] + shift - c) / count) * count + c;
            se += (th[k] - qk) * (th[k] - qk);
          }
          if (se < best) { best = se; best_shift = shift; }
        }
        for (size_t k = 0; k < n; ++k) {
          quant[k] = std::round((line[k] + err[k] + best_shift - c) / count) * count + c - line[k];
        }
      } else {
        quant = err;
      }
      std::vector<Complex> ain(n), aout, qin(n), qout;
      for (size_t k = 0; k < n; ++k) {
        ain[k] = Complex((th[k] - line[k]) * win[k], 0.0);
        qin[k] = Complex(quant[k] * win[k], 0.0);
      }
      fft.fwd(aout, ain);
      fft.fwd(qout, qin);
      wp.spectrum_angle.assign(aout.begin(), aout.end());
      wp.spectrum_angle_model.assign(qout.begin(), qout.end());
      // The sawtooth's harmonics (k times the slip rate, aliased) are the
      // channel's nuisance where the model leaves a little of them (a
      // reading whose transitions fall a fraction of a sample off the
      // ideal ramp's: 8 % of a count at 150 rpm on a measured-map bench).
      if (count > 0) {
        const double cps = slope / count, slip = std::abs(cps - std::round(cps)) * fs;
        if (slip > 0) {
          // A named angle error (err) modulates the slip rate at twice the
          // electrical frequency: the sawtooth's lines then carry sidebands
          // at +-2 j f_e, as sensitive to the error's exact size as the
          // transitions are.
          bool modulated = false;
          for (double e : err) modulated |= e != 0.0;
          const int sidebands = modulated ? 3 : 0;
          for (int k = 1; k <= 200 && k * slip < 40 * fs; ++k) {
            for (int j = -sidebands; j <= sidebands; ++j) {
              const double f = std::remainder(k * slip + 2.0 * j * wp.f_e_hz, fs);
              wp.angle_nuisance_hz.push_back(f);
              wp.angle_nuisance_hz.push_back(-f);
            }
          }
        }
      }
      const std::vector<bool> quiet_currents = quiet;
      for (size_t b = 0; b < n; ++b) {
        for (double f : wp.angle_nuisance_hz) {
          if (std::abs(wp.freq_hz[b] - f) <= tol) quiet[b] = false;
        }
      }
      wp.sigma2_bin_angle = noise_of(aout, true);
      detect(aout, wp.sigma2_bin_angle, "rotor_angle");
      quiet = quiet_currents;
    }
    out.push_back(std::move(wp));
  }
  return out;
}

}  // namespace fluxcal::diag::detail
