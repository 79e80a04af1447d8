// Joint Ceres fit of a conservative flux-linkage model to every kind of data
// a recording set carries (docs/fitting.md):
//   - differential inductances (Ldd, Lqq, Ldq) per operating point, weighted
//     by their standard errors (floored at a model-adequacy level);
//   - steady-state flux linkages from ud, uq at speed (corrected for the
//     inverter's one-period delay and zero-order hold);
//   - torque where present;
//   - psi_pm from the manifest as a prior.
// Build / Solve / Report are separate; model selection by BIC across the
// analytic family and polynomial co-energies of rising degree.
#ifndef FLUXCAL_FITTING_FIT_H_
#define FLUXCAL_FITTING_FIT_H_

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "io/recording_set.h"

namespace fluxcal::ident {
struct HfPointResult;
}
namespace fluxcal::io {
struct FluxMap;
}

namespace fluxcal::fit {

struct HfOrbitWeights;   // fitting/inductance_residual.h

struct InductanceObservation {
  double id_a = 0, iq_a = 0;
  double ldd_h = 0, lqq_h = 0;
  std::optional<double> ldq_h;
  double ldd_h_std = 0, lqq_h_std = 0, ldq_h_std = 0;
  // The radius of the flux circle the point's rotating-voltage injection
  // drove, |V| / w_i (physics/hf_orbit.h), Wb; unset where the source does
  // not say (the point is then taken as small-signal: the Jacobian at
  // (id, iq)). Set, Fit predicts the point as what the injection measures,
  // the describing function over the current's orbit (docs/fitting.md,
  // "Large-signal HF").
  std::optional<double> hf_flux_radius_wb;
  // That orbit, computed by Fit from its first pass where the radius is
  // set; given without a radius, it is used as it is.
  std::shared_ptr<const HfOrbitWeights> hf_orbit;
  // The temperature the bench recorded for the point, degC (the manifest's
  // points[].temperature_c, hf_results.csv's temperature_c); unset: none
  // recorded. Read as the magnet temperature (Fit, magnet reference).
  std::optional<double> temperature_c{};
};

struct SteadyStateObservation {
  double id_a = 0, iq_a = 0, speed_rpm = 0, ud_ref_v = 0, uq_ref_v = 0;
  std::optional<double> torque_nm;
  // What the bench held over the row's averaging window, as the recording's
  // extension columns state it (docs/recording-format.md, "Rows a bench
  // could not hold"; absent: not reported): the measured dq current's RMS
  // deviation from its mean (A), and the shares (0..1) of the window with
  // the modulator at its voltage limit and with the current controller
  // clamped. The fit excludes a row the bench did not hold and widens the
  // flux sigma of a rippled one (fitting/screen.cc, problem.cc).
  std::optional<double> current_ripple_a{};
  std::optional<double> voltage_limited_share{};
  std::optional<double> controller_saturated_share{};
  // The row's recorded temperature_c, degC; unset: empty cell.
  std::optional<double> temperature_c{};
};

// A flux linkage known directly: a measured or FEA flux map's node
// (io/flux_map.h), sigma its standard deviation per component.
struct FluxObservation {
  double id_a = 0, iq_a = 0, psi_d_wb = 0, psi_q_wb = 0, psi_std_wb = 0;
  // The magnet temperature of the node, degC; unset: not stated (a map
  // file carries none; `fluxcal fit --magnet-reference-c` states it).
  std::optional<double> temperature_c{};
};

// What the data say about the machine and drive comes from the set's
// manifest, a flux map's caller or command-line flags; a fact nobody stated
// stays unknown (0 / nullopt), never a default of some other machine.
struct FitData {
  std::string serial;
  int pole_pairs = 0;                       // required: Fit refuses 0 (unknown)
  // Nominal stator resistance, for the steady-state fluxes (unknown: the
  // resistive drop is neglected there, and the calibration records Rs
  // unknown).
  std::optional<double> rs_ohm;
  double f_pwm_hz = 10000.0;                // for the inverter-delay correction
  // The magnet flux the data source states (manifest motor.psi_pm_wb, a
  // flag, a flux map's node at zero current): the fit's prior, and the
  // calibration's nominal psi_pm.
  std::optional<double> psi_pm_prior_wb;
  // DC-link voltage of the drive (manifest drive.udc_v, or a flag); carried
  // into the calibration for the voltage limit of its tables.
  std::optional<double> udc_v;
  // Relative change of psi_pm per kelvin of magnet temperature (manifest
  // motor.psi_pm_temp_coeff_per_k, or --magnet-temp-coeff-per-k); carried
  // into the calibration for tables at another magnet temperature.
  std::optional<double> psi_pm_temp_coeff_per_k;
  std::vector<InductanceObservation> inductances;
  std::vector<SteadyStateObservation> steady_state;
  std::vector<FluxObservation> fluxes;
};

// A model name as `fluxcal fit --model`, `fluxcal eol --model` and the Fit
// RPC's `model` field give it, parsed in this one place: Fit builds its
// candidates from it, and `fluxcal fit` calls it before the (slow)
// identification so that a typo costs nothing. (The CLI once kept its own
// copy, which refused "poly3x" while Fit's std::stoi read it as poly3.)
struct ModelName {
  enum Kind { kAuto, kAnalytic, kPoly, kSpline, kSmooth, kSmoothAsym };
  Kind kind = kAuto;
  // kPoly: the degree 2..10, kSpline: the spans 1..8; 0 for "poly" /
  // "spline": every degree 3..8 / spans 1..4, chosen by cross-validation.
  int n = 0;
};
// "auto", "analytic", "poly", "polyN" (N 2..10), "spline", "splineN" (N
// 1..8), "smooth" or "smooth-asym"; N as absl::SimpleAtoi reads it (no
// trailing characters). Anything else is InvalidArgument naming the flag
// --model and every accepted name.
absl::StatusOr<ModelName> ParseModelName(const std::string& name);

struct FitOptions {
  // A name ParseModelName accepts: "auto" (BIC over all), "analytic",
  // "poly" (BIC over degrees), "polyN", ...
  std::string model = "auto";
  // Relative floor on inductance standard errors: the data are not more
  // precise than the model family can represent (0.2 %).
  double relative_sigma_floor = 0.002;
  double psi_pm_prior_relative_std = 0.05;
  // Robust loss scale in standard deviations (Huber; fitting/solve_linear.cc says why).
  double robust_scale = 3.0;
  // Treat the differential inductance as apparent (psi = psi_pm + L i):
  // only for demonstrating the error (tests); never in production.
  bool differential_as_apparent = false;
  // The smoothing splines' penalty anisotropy kappa (surface.h,
  // SmoothingPenalty): unset, the fit chooses it by the restricted
  // likelihood over its grid (select.cc); set, that kappa alone (a caller
  // refitting the same machine's data, e.g. the diagnosis after each
  // finding, keeps the one its baseline chose: one penalty, not seven).
  std::optional<double> smoothing_anisotropy_q;
  // The smoothing splines' curvature weight mu (surface.h,
  // SmoothingPenalty): unset, kSmoothingCurvatureWeight; 0, the penalty on
  // the inductance's slopes alone (the diagnosis' baseline, diagnosis/
  // observations.cc says why).
  std::optional<double> smoothing_curvature_weight;
  // Predict HF points whose injection's flux radius is known as the
  // describing function over their orbit (InductanceObservation::
  // hf_flux_radius_wb): a second pass on the first pass's orbits. False: the
  // small-signal Jacobian at every point's mean current (callers whose own
  // forward model is small-signal, e.g. the diagnosis' phasor replays).
  bool large_signal_hf = true;
  // Polled before each candidate family: true stops the fit with Cancelled
  // (a server's client deadline passed).
  std::function<bool()> cancelled;
};

// Observations from identification results / a set's hf_results rows;
// serial, pole pairs, Rs, psi_pm and Udc from the manifest as it states
// them (without a manifest: all unknown).
FitData FitDataFromRecording(const io::RecordingSet& set,
                             const std::vector<ident::HfPointResult>& identified);
// The flux radius of an identified point (InductanceObservation::
// hf_flux_radius_wb): |v_eff| / w_i of a rotating injection the manifest
// states; unset for any other injection or none.
std::optional<double> HfFluxRadiusOf(const io::Manifest& manifest, const ident::HfPointResult& identified);
FitData FitDataFromHfRows(const io::Manifest* manifest, const std::vector<io::HfResultRow>& rows);
// Observations from a flux map's nodes (io/flux_map.h): each node a
// FluxObservation with standard deviation psi_std_wb per component (<= 0:
// 0.2 % of the map's largest |psi|, the relative floor the fit also puts on
// inductances), and psi_pm's prior from the node at (0, 0) when the map has
// one with psi_d > 0. Serial, Rs and Udc stay unknown: a map carries none
// of them (nor pole pairs, which the caller gives).
FitData FitDataFromFluxMap(const io::FluxMap& map, int pole_pairs, double psi_std_wb = 0.0);

// The magnet temperature of the observations a fit used
// (docs/recording-format.md, "Magnet temperature"): the mean and the spread (max - min) of their
// recorded temperature_c when every one of them records one; nullopt when
// any does not (or there are none). Fit stores it in the calibration.
struct MagnetReference {
  double mean_c = 0, spread_k = 0;
};
std::optional<MagnetReference> MagnetReferenceOf(const FitData& used);

// The calibration of `data` (InvalidArgument naming 'pole_pairs' when they
// are unknown: torque and speed need them): observations that are not data screened out
// (non-finite or non-positive values, rows outside the measured region or
// not a steady state), every candidate family fitted, the physical one with
// the lowest cross-validation score kept; what was left out or
// down-weighted is listed in summary.excluded with its reason (screen.cc, select.cc).
// The candidates are symmetric in iq (psi_d even, psi_q odd) unless the data
// measured both halves of the iq axis (then smooth-asym too); the
// calibration records the halves measured (Calibration::iq_halves), so a
// prediction on the other half says "by symmetry" or "extrapolated".
absl::StatusOr<Calibration> Fit(const FitData& data, const FitOptions& options = {});

// Flux linkage measured by a steady-state row: psi_d = (uq' - Rs iq)/w,
// psi_q = -(ud' - Rs id)/w with u' the command corrected for the delay
// (Rs unknown: the resistive drop is neglected).
void SteadyStateFlux(const SteadyStateObservation& s, int pole_pairs, std::optional<double> rs_ohm,
                     double f_pwm_hz, double* psi_d_wb, double* psi_q_wb);

}  // namespace fluxcal::fit

#endif  // FLUXCAL_FITTING_FIT_H_
