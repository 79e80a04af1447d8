// Diagnosis: compare the nominal model of a recording set with the
// recordings, locate significant mismatches, explain them with candidate
// physics (docs/diagnosis-report.md effect names), refit, and report in the
// fluxcal.diagnosis.v1 format. Method and statistics: docs/diagnosis.md.
#ifndef FLUXCAL_DIAGNOSIS_DIAGNOSE_H_
#define FLUXCAL_DIAGNOSIS_DIAGNOSE_H_

#include <functional>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "fitting/fit.h"
#include "io/recording_set.h"

namespace fluxcal::diag {

// A physical hypothesis for a located mismatch (docs/diagnosis.md,
// "Naming what is not modelled"): what it is, whether the catalogue models
// it, and what it would show elsewhere in the recordings.
struct Hypothesis {
  std::string physics;
  std::string effect;        // its catalogue name, "" when outside the catalogue
  std::string predicts;      // what else it would do (the test that tells it apart)
};

struct Mismatch {
  std::string signal;          // hf_current | dc_voltage | steady_state_voltage | torque |
                               // phase_current | zero_sequence_current (waveforms)
  std::string where;           // human description of the region
  std::vector<std::string> points;
  double significance_sigma = 0;
  // Waveform-level mismatches (compatible extension, docs/diagnosis-report.md):
  // the kind of component ("electrical_harmonic", "mechanical_order",
  // "injection_sideband", "injection_harmonic", "fixed_frequency_line",
  // "unexplained_line", "angle_pattern", "region"), its order (harmonic
  // number, mechanical order, rotor-angle order; 0 when none), its
  // frequency at the points where it was seen (Hz; 0 when it moves with
  // speed), its size (largest amplitude, A), and how it depends on the
  // recording order, the current magnitude and the speed.
  std::string kind;
  int order = 0;
  double frequency_hz = 0;
  double size_a = 0;
  std::string dependence;
  std::vector<Hypothesis> hypotheses;   // ranked, most likely first
};

// An effect the data cannot tell apart from a finding (same signature in
// every observable of the set), with the parameters it would have and why
// the set does not separate them (docs/diagnosis.md).
struct AlternativeExplanation {
  std::string effect;
  std::map<std::string, double> parameters;
  std::string why;
};

struct Finding {
  std::string effect;
  std::string explanation;
  std::map<std::string, double> parameters, parameter_std;
  double residual_rms_before = 0, residual_rms_after = 0, delta_bic = 0;
  std::vector<AlternativeExplanation> alternatives;
};

struct ModelSummary {
  std::string model;
  double residual_rms = 0, bic = 0, chi2 = 0;
};

struct CorrectedPoint {
  std::string point;
  double id_a = 0, iq_a = 0;
  double ldd_h = 0, lqq_h = 0, ldq_h = 0;              // final model
  double ldd_h_identified = 0, lqq_h_identified = 0;   // as identified
};

// Honesty check of the final model (docs/diagnosis.md): refitted without one
// observable class, how well it predicts that class.
struct HeldOutCheck {
  std::string signal;               // the class left out of the fit
  double significance_sigma = 0;    // largest region significance of its prediction error
  double residual_rms = 0;          // relative RMS of its prediction error
  // Where the class measures the flux itself (steady-state voltages,
  // torque) and its prediction missed: the largest move of an effect
  // parameter refitted without it, in standard deviations of the
  // difference (Hausman; negative: not used).
  double parameter_shift_sigma = -1;
  // Whether that move reaches some parameter's materiality floor (only
  // then can it fail the class; verdict.cc, MaterialMove).
  bool parameter_shift_material = true;
  bool passed = false;
};

// A candidate the last selection round did not accept, and why.
struct RejectedCandidate {
  std::string effect;
  std::string reason;
  double delta_bic = 0, significance = 0;
};

struct DiagnosisReport {
  std::string serial;
  std::string verdict;   // no_mismatch | explained | partly_explained | unexplained
  ModelSummary baseline, final_model;
  std::vector<Mismatch> mismatches;          // located against the baseline
  std::vector<Mismatch> remaining;           // still significant after the refit
  std::vector<Finding> findings;             // in acceptance order
  std::vector<HeldOutCheck> held_out;        // predictions of classes left out of the fit
  std::vector<RejectedCandidate> rejected;   // best candidates of the last round, not accepted
  std::vector<CorrectedPoint> corrected;     // inductances of the final model
  // The recording's fit data freed of the found effects (DiagnosedCalibration).
  fit::FitData corrected_data;
  // Per-observable normalised residuals before/after, for plots.
  struct Residual {
    std::string point, signal;
    double id_a = 0, iq_a = 0, speed_rpm = 0, before = 0, after = 0;
  };
  std::vector<Residual> residuals;
  // Waveform evidence: every recorded test replayed open-loop through the
  // twin (recorded commands, recorded angle) with the nominal and with the
  // final model; RMS of simulated minus recorded phase currents, and the
  // residual's spectrum (stationary frame, complex, signed frequency).
  double waveform_rms_before_a = 0, waveform_rms_after_a = 0;
  std::vector<double> spectrum_hz, spectrum_before_a, spectrum_after_a;
  // Frequencies where the residual stands out: bins above 10x (20 dB) the
  // median bin of the same spectrum (the data's own broadband floor).
  std::vector<double> significant_hz_before, significant_hz_after;
  double seconds = 0;
};

struct DiagnoseOptions {
  double bic_threshold = 10.0;      // docs/diagnosis-report.md
  double parameter_sigma = 3.0;     // parameter distance from neutral
  double mismatch_sigma = 5.0;      // a located region's significance
  double min_relative_improvement = 0.10;   // residual RMS drop to accept an effect
  // A class left out of the final fit is predicted when no region of it is
  // more significant than this (docs/diagnosis.md, "Honesty").
  double heldout_sigma = 5.0;
  double heldout_fraction = 0.02;   // ... or this share of the class's located significance
  bool waveform_replay = true;              // replay evidence and spectra
  // Estimate the inverter's soft-sign current i_th when a dead time or a
  // switch threshold is found (diagnose.cc); off: i_th = 1 A throughout.
  bool profile_soft_sign = true;
  // Catalogue rows left out of the candidates (probes of physics outside
  // the vocabulary: conceal an effect, exclude its row).
  std::set<std::string> excluded_effects;
  // Polled before each candidate refit: true stops the diagnosis with
  // Cancelled (a server's client deadline passed).
  std::function<bool()> cancelled;
};

absl::StatusOr<DiagnosisReport> Diagnose(const io::RecordingSet& set, const DiagnoseOptions& options = {});

// The diagnosed model as a calibration: the corrected data refitted through
// the fit's own families (fitting::Fit), ready for `fluxcal export`.
absl::StatusOr<fit::Calibration> DiagnosedCalibration(const DiagnosisReport& r,
                                                      const fit::FitOptions& options = {});

// `cal`'s calibration JSON marked with the diagnosis ("diagnosis": format,
// verdict, findings with their parameters), as `diagnose --calibration-out`
// writes it and the service stores it.
nlohmann::json MarkedCalibrationJson(const DiagnosisReport& r, const fit::Calibration& cal);

nlohmann::json ToJson(const DiagnosisReport& r);
std::string ToText(const DiagnosisReport& r);
// Residual maps over the current plane, before and after (SVG).
std::string ResidualMapSvg(const DiagnosisReport& r, bool after);
// Spectrum of the replay residual, before and after (SVG).
std::string SpectrumSvg(const DiagnosisReport& r);

// The paper's Table 1 check (Wu, Wu, Zhu 2013): HF-identified Lq against
// Lq = u_d*/(w_e i_q) from steady-state control at id = 0. The steady-state
// value is an apparent inductance; comparing it with the differential one
// leaves a mismatch that grows with current (`differential_inductance`).
struct Table1Row {
  double iq_a = 0, lq_hf_h = 0, lq_ss_h = 0;
};
struct Table1Result {
  double rms_before = 0, rms_after = 0;      // relative, vs steady-state values
  std::vector<double> lq_app_from_hf_h;      // apparent from integrating Lqq
  double trend_slope_per_a = 0, trend_sigma = 0;   // mismatch growth with current
  std::string finding;                       // "differential_inductance" or ""
  double max_before = 0, max_after = 0;      // largest relative errors
  // What else could explain the error left after integrating: one-parameter
  // hypotheses on the rows with iq > 0 (the formula u_d/(w_e i_q) needs
  // current), each with its fitted parameter, the relative errors it leaves
  // and BIC against "estimation noise only" (docs/diagnosis.md, Table 1).
  struct Alternative {
    std::string name, meaning;
    double parameter = 0;          // in the unit `unit` says
    std::string unit;
    double rms = 0, max = 0, delta_bic = 0;
  };
  std::vector<Alternative> alternatives;
};
absl::StatusOr<std::vector<Table1Row>> ReadTable1(const std::string& path);
Table1Result DiagnoseTable1(const std::vector<Table1Row>& rows);

}  // namespace fluxcal::diag

#endif  // FLUXCAL_DIAGNOSIS_DIAGNOSE_H_
