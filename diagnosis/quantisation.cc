// The sensors' resolution in the waveform locator (docs/diagnosis.md, "The
// waveforms"): a current sampled in steps of q with little noise before the
// quantiser is not dithered, and the quantiser's error then follows the
// signal -- lines at a periodic current's harmonics and their
// intermodulation, which the replay does not make. Here: the step read
// from the recording, the quantiser's mean error computed on the simulated
// current, and the power it puts in each bin of the residual's spectra, a
// bin's third noise term beside the white floor and the model's own line
// (waveform.cc).
#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <vector>

#include <unsupported/Eigen/FFT>

#include "diagnosis/internal.h"
#include "simulation/frames.h"

namespace fluxcal::diag::detail {
namespace {

// The mean error a quantiser of step q makes on an input x carrying
// Gaussian noise of standard deviation sigma before it. The error
// e(x) = Q(x) - x is periodic in the input with period q, a sawtooth:
//   e(x) = sum_j (-1)^j (q / (pi j)) sin(2 pi j x / q),
// and the noise scales its j-th term by the Gaussian characteristic
// function exp(-2 pi^2 j^2 sigma^2 / q^2) (Widrow & Kollar, Quantization
// Noise, 2008, ch. 4-5); the rest of the error is white. This mean follows
// the signal: for a periodic current it is a set of lines at the signal's
// harmonics and their intermodulation (AnalyseWaveforms).
double MeanQuantisationError(double x, double q, const double* attenuation, int terms) {
  double e = 0;
  for (int j = 1; j <= terms; ++j) {
    e += (j % 2 ? -1.0 : 1.0) * q / (kPi * j) * attenuation[j - 1] * std::sin(2 * kPi * j * x / q);
  }
  return e;
}
constexpr int kQuantisationTerms = 8;
// Offsets of the simulated current against the quantiser's grid over which
// its lines' power is averaged: the replay follows the recorded current to
// more than a step, so where on the grid the signal sits is not known.
constexpr int kQuantisationOffsets = 4;

}  // namespace

// The step of the recorded phase currents' quantisation, A: the largest
// over the three phases of the grid every sample lies on (each phase its
// own: a bench may scale each ADC's codes by its own gain). A phase's
// grid is the smallest difference between its distinct values, refined by
// least squares over the samples, when at least 99 % of them lie within
// 5 % of a step of a whole number of steps from the first (the rest:
// print rounding). Samples on no grid coarser than their print precision
// give that precision, whose lines are negligible (MeanQuantisationError).
double CurrentStepA(const io::Waveform& w) {
  double step = 0;
  for (const std::vector<double>* v : {&w.ia_a, &w.ib_a, &w.ic_a}) {
    if (v->size() < 64) continue;
    // A non-finite sample (the readers refuse them; this is a second line)
    // would break the sort's ordering: no grid is read from such a phase.
    if (!std::all_of(v->begin(), v->end(), [](double x) { return std::isfinite(x); })) continue;
    std::vector<double> s(*v);
    std::sort(s.begin(), s.end());
    s.erase(std::unique(s.begin(), s.end()), s.end());
    if (s.size() < 16) continue;
    double d = std::numeric_limits<double>::infinity();
    for (size_t k = 1; k < s.size(); ++k) d = std::min(d, s[k] - s[k - 1]);
    if (!(d > 0) || !std::isfinite(d)) continue;
    const double x0 = s.front();
    double skk = 0, skx = 0;
    size_t on = 0;
    for (double x : *v) {
      const double u = (x - x0) / d;
      const double k = std::round(u);
      if (std::abs(u - k) <= 0.05) ++on;
      skk += k * k;
      skx += k * (x - x0);
    }
    if (static_cast<double>(on) < 0.99 * static_cast<double>(v->size()) || skk <= 0) continue;
    step = std::max(step, skx / skk);
  }
  return step;
}

// Per point: with n the spectra's length (samples 1..n of the record) and
// `win` their window, the mean error on the simulated current at
// kQuantisationOffsets places on the grid, transformed as the residual is
// (alpha-beta, zero sequence), its power averaged over the places. The
// noise before the quantiser is the residual's white noise less the
// quantisation's white share q^2 / 12.
void QuantisationSpectra(const io::Waveform& w, const sim::ReplayPoint& r, const std::vector<double>& win,
                         WaveformPoint* out) {
  WaveformPoint& wp = *out;
  const size_t n = win.size();
  if (r.ia_a.size() < n + 1) return;
  const double q = CurrentStepA(w);
  wp.current_step_a = q;
  if (!(q > 0)) return;
  const double sigma2 = std::max(0.0, wp.noise_a * wp.noise_a - q * q / 12.0);
  double att[kQuantisationTerms];
  for (int j = 1; j <= kQuantisationTerms; ++j) att[j - 1] = std::exp(-2.0 * kPi * kPi * j * j * sigma2 / (q * q));
  // Terms the noise has not smoothed away (a term below 1e-6 of the
  // undithered one is below any line a record can show).
  int terms = 0;
  while (terms < kQuantisationTerms && att[terms] > 1e-6) ++terms;
  if (terms == 0) return;   // dithered: the error is white, in the floor
  wp.quant2.assign(n, 0.0);
  wp.quant2_zero.assign(n, 0.0);
  Eigen::FFT<double> fft;
  std::vector<Complex> qin(n), q0in(n), qout, q0out;
  for (int o = 0; o < kQuantisationOffsets; ++o) {
    const double delta = q * o / kQuantisationOffsets;
    for (size_t k = 0; k < n; ++k) {
      const size_t s = k + 1;   // sample 0 is not simulated (ReplayOpenLoop)
      const double ea = MeanQuantisationError(r.ia_a[s] + delta, q, att, terms);
      const double eb = MeanQuantisationError(r.ib_a[s] + delta, q, att, terms);
      const double ec = MeanQuantisationError(r.ic_a[s] + delta, q, att, terms);
      const sim::AlphaBeta ab = sim::Clarke(ea, eb, ec);
      qin[k] = Complex(ab.alpha, ab.beta) * win[k];
      q0in[k] = Complex((ea + eb + ec) / 3.0 * win[k], 0.0);
    }
    fft.fwd(qout, qin);
    fft.fwd(q0out, q0in);
    for (size_t b = 0; b < n; ++b) {
      wp.quant2[b] += std::norm(qout[b]) / kQuantisationOffsets;
      wp.quant2_zero[b] += std::norm(q0out[b]) / kQuantisationOffsets;
    }
  }
}

// The power the quantiser's mean error puts in bin b of a channel's
// spectrum (0 for the angle channel, or without a step).
double QuantisationPower(const WaveformPoint& wp, const std::string& channel, size_t b) {
  const std::vector<double>* q = channel == "phase_current"           ? &wp.quant2
                                 : channel == "zero_sequence_current" ? &wp.quant2_zero
                                                                      : nullptr;
  return q != nullptr && b < q->size() ? (*q)[b] : 0.0;
}

}  // namespace fluxcal::diag::detail
