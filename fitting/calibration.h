// A fitted calibration: flux-linkage surfaces psi_d(id, iq), psi_q(id, iq)
// of one motor serial, their parameter covariance and the measured region.
// Implements sim::MagneticModel, so the twin can replay it and the table
// generators can use it directly. Serialises to JSON and back exactly
// (format "fluxcal.calibration.v1"; doubles written with 17 digits). The
// parameter covariance is held at float precision (symmetric, each entry
// rounded to float when the calibration is constructed: by the fit and by
// FromJson), so its binary form (pipeline/calibration_codec.h) is exact.
//
// It carries what the set (or the flags of `fluxcal fit`) stated about the
// machine and drive: pole pairs (always known: a fit refuses without
// them), and where stated the nominal Rs, the nominal psi_pm and the
// DC-link voltage. A fact not stated is absent (nullopt; absent from the
// JSON), never another machine's default; docs/fitting.md.
#ifndef FLUXCAL_FITTING_CALIBRATION_H_
#define FLUXCAL_FITTING_CALIBRATION_H_

#include <optional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "absl/status/statusor.h"
#include "fitting/flux_family.h"
#include "simulation/magnetic_model.h"

namespace fluxcal::fit {

// Where an operating point lies relative to the data a calibration was
// fitted to (Calibration::RegionOf):
//  kMeasured: inside the measured region (the box the observations span,
//    2 % margin, on the iq half or halves the data measured);
//  kBySymmetry: the mirror image (id, -iq) of a measured point, on the
//    half the data did not measure, of a model symmetric in iq (psi_d even,
//    psi_q odd): what it says there is the measured half mirrored;
//  kExtrapolated: anything else, including the unmeasured half of a model
//    that is not symmetric in iq (smooth-asym asked for by name on data
//    from one half).
enum class Region { kMeasured, kBySymmetry, kExtrapolated };
// "measured", "by_symmetry", "extrapolated" (JSON, proto, CSV).
const char* RegionName(Region r);

// Which halves of the iq axis the data measured (Fit decides: select.cc,
// MeasuredIqOf). kUnknown: a calibration written before this was recorded
// (no `iq_halves` in its JSON) or built without it; its |iq| box counts as
// measured on both halves, as it always did.
enum class IqHalves { kUnknown, kPositive, kNegative, kBoth };
const char* IqHalvesName(IqHalves h);   // "unknown", "positive", "negative", "both"

// Why a differential inductance is not positive definite ("" when it is):
// Ldd > 0, Lqq > 0 and det = Ldd Lqq - Ldq^2 > 0 (Sylvester's criterion for
// the symmetric 2 x 2 matrix [[Ldd, Ldq], [Ldq, Lqq]]). A non-finite value
// is not positive definite. The one test of it: the fit's physical check,
// queries and the tables' per-cell flag all call this.
std::string NotPositiveDefiniteReason(double ldd_h, double lqq_h, double ldq_h);

struct FluxPrediction {
  double psi_d_wb = 0, psi_q_wb = 0, ldd_h = 0, lqq_h = 0, ldq_h = 0;
  double ld_app_h = 0, lq_app_h = 0, torque_nm = 0;
  double psi_d_wb_std = 0, psi_q_wb_std = 0, ldd_h_std = 0, lqq_h_std = 0, ldq_h_std = 0;
  double ld_app_h_std = 0, lq_app_h_std = 0, torque_nm_std = 0;
  Region region = Region::kMeasured;
  bool extrapolated = false;   // region == kExtrapolated
  // false when the differential inductance is not positive definite there
  // (invalid_reason says which test failed): such a point is never a valid
  // operating point of the model, whatever its region.
  bool valid = true;
  std::string invalid_reason;
};

struct FitSummary {
  int observations = 0;
  double chi2 = 0, bic = 0, rms_relative = 0;
  std::string termination;
  bool usable = false;
  // The selected family's effective parameters (tr H of a penalised fit)
  // and, for a smoothing spline, the penalty weight lambda it was fitted
  // with (solve_linear.cc, SolveLinear): what a refit of the same surfaces with other
  // unknowns beside them (diagnosis) keeps them as smooth with.
  double effective_parameters = 0, smoothing_lambda = 0;
  double smoothing_anisotropy_q = 1;   // SmoothingPenalty's kappa with smoothing_lambda (surface.h)
  // SmoothingPenalty's curvature weight mu: 0 in calibrations written before
  // it existed (third derivatives only), kSmoothingCurvatureWeight since.
  double smoothing_curvature_weight = 0;
  std::vector<std::string> candidates;   // model-selection table "name cv bic ..."
  // Observations the fit left out or the robust loss down-weighted, each
  // with its point and reason ("hf point 31 (id 0 A, iq 0 A): ldd_h ...").
  std::vector<std::string> excluded;
  // A fit to flux nodes (a flux map, FitData::fluxes; rms_relative above
  // covers identified inductances, which a map has none of): the flux
  // error over those nodes, fitting/flux_error.h. flux_nodes = 0: no flux
  // nodes were fitted and the flux_* fields are 0 (and absent from JSON).
  int flux_nodes = 0;
  double flux_rms_relative = 0, flux_max_relative = 0;   // of flux_scale_wb
  double flux_rms_wb = 0, flux_max_wb = 0, flux_scale_wb = 0;
};

class Calibration : public sim::MagneticModel {
 public:
  Calibration() = default;
  Calibration(std::string serial, Family family, std::vector<double> params,
              std::vector<double> covariance, int pole_pairs, std::optional<double> rs_ohm,
              double id_min_a, double id_max_a, double iq_min_a, double iq_max_a);

  sim::FluxLinkage Flux(double id_a, double iq_a, double temperature_c = 25.0) const override;
  sim::DifferentialInductance Inductance(double id_a, double iq_a,
                                         double temperature_c = 25.0) const override;
  void FluxAndInductance(double id_a, double iq_a, double temperature_c, sim::FluxLinkage* flux,
                         sim::DifferentialInductance* inductance) const override;
  // Everything at one point with standard deviations from the parameter
  // covariance (first-order propagation), its region and its validity.
  FluxPrediction Predict(double id_a, double iq_a) const;

  const std::string& serial() const { return serial_; }
  const Family& family() const { return family_; }
  const std::vector<double>& params() const { return params_; }
  const std::vector<double>& covariance() const { return covariance_; }
  int pole_pairs() const { return pole_pairs_; }
  // Nominal stator resistance as stated (manifest motor.rs_ohm, --rs-ohm).
  const std::optional<double>& rs_ohm() const { return rs_ohm_; }
  // The fitted magnet flux (the model's first parameter).
  double psi_pm_wb() const { return params_.empty() ? 0.0 : params_[0]; }
  // The magnet flux the data source stated (manifest motor.psi_pm_wb,
  // --psi-pm-wb, a flux map's node at zero current): the fit's prior and
  // what the verdict judges psi_pm against.
  const std::optional<double>& psi_pm_nominal_wb() const { return psi_pm_nominal_wb_; }
  void set_psi_pm_nominal_wb(std::optional<double> v) { psi_pm_nominal_wb_ = v; }
  // DC-link voltage of the drive the data came from (manifest drive.udc_v,
  // --udc-v): the voltage limit of field-weakening and MTPV exports.
  const std::optional<double>& udc_v() const { return udc_v_; }
  void set_udc_v(std::optional<double> v) { udc_v_ = v; }
  // Magnet temperature (docs/recording-format.md, "Magnet temperature"): the
  // relative change of psi_pm per kelvin as stated (manifest
  // motor.psi_pm_temp_coeff_per_k, --magnet-temp-coeff-per-k), and the
  // magnet temperature of the flux map, degC: the mean of the recorded
  // temperature_c of the observations the fit used (or
  // --magnet-reference-c), with their spread max - min, K (0 for a stated
  // one). Unset: not stated / not recorded. Together they give psi_pm(T) =
  // psi_pm(T_ref) (1 + alpha (T - T_ref)) (tables::MagnetTemperatureOf).
  const std::optional<double>& psi_pm_temp_coeff_per_k() const { return psi_pm_temp_coeff_per_k_; }
  void set_psi_pm_temp_coeff_per_k(std::optional<double> v) { psi_pm_temp_coeff_per_k_ = v; }
  const std::optional<double>& magnet_reference_c() const { return magnet_reference_c_; }
  const std::optional<double>& magnet_reference_spread_k() const { return magnet_reference_spread_k_; }
  // A spread without a reference is dropped (it says nothing alone).
  void set_magnet_reference(std::optional<double> reference_c, std::optional<double> spread_k) {
    magnet_reference_c_ = reference_c;
    magnet_reference_spread_k_ = reference_c ? spread_k : std::nullopt;
  }
  // Measured, by symmetry or extrapolated (Region above).
  Region RegionOf(double id_a, double iq_a) const;
  // RegionOf(...) != kExtrapolated: measured, or the mirror image of a
  // measured point under the symmetry of a symmetric model.
  bool InMeasuredRegion(double id_a, double iq_a) const;
  double id_min_a() const { return id_min_a_; }
  double id_max_a() const { return id_max_a_; }
  // Fit stores the range of |iq| here, and the signed extent of the halves
  // it measured below.
  double iq_min_a() const { return iq_min_a_; }
  double iq_max_a() const { return iq_max_a_; }
  // The iq halves the data measured and their signed extent: iq in
  // [iq_signed_min_a, iq_signed_max_a] (with the 2 % margin) is measured
  // (a half the data did not measure ends the range at 0). Fit sets them;
  // without (kUnknown) the |iq| box is measured on both halves.
  void SetMeasuredIq(IqHalves halves, double iq_signed_min_a, double iq_signed_max_a);
  IqHalves iq_halves() const { return iq_halves_; }
  // One sentence on the iq range measured and what the calibration says on
  // the other half ("iq 0 .. 24 A measured; iq -24 .. 0 A by symmetry
  // (...)"), for pages and summaries.
  std::string IqRegionText() const;
  // One sentence on the magnet temperature dependence the calibration
  // states (coefficient, reference, spread) or what it lacks for one.
  std::string MagnetTemperatureText() const;
  double iq_signed_min_a() const { return iq_signed_min_a_; }
  double iq_signed_max_a() const { return iq_signed_max_a_; }
  // Inductance positive definite (Ldd > 0, Lqq > 0, det > 0) on a grid over
  // the measured region widened by `factor` (towards negative id and larger
  // |iq|): the extrapolation a table generator may lean on stays physical.
  // A model symmetric in iq is checked on iq >= 0 (the other half is its
  // mirror image); one that is not, over the signed iq range measured.
  // (Saturation beyond the region is guaranteed by the analytic family only.)
  // Grid nodes inside a box of `except` (|iq|) are not checked: Fit passes
  // the cells around a point the bench measured non-positive, where the
  // data say the machine's map is not positive definite.
  struct Box {
    double id_lo_a, id_hi_a, abs_iq_lo_a, abs_iq_hi_a;
  };
  bool PhysicalOver(double factor, const std::vector<Box>& except = {}) const;
  // Largest current magnitude whose quarter circle stays in the measured
  // region (min(|id_min|, iq_max)); the tables' default current limit.
  double MeasuredCurrentLimitA() const;
  FitSummary summary;
  int version = 0;   // assigned by storage

  nlohmann::json ToJson() const;
  static absl::StatusOr<Calibration> FromJson(const nlohmann::json& j);

 private:
  // The covariance made symmetric and rounded to float (calibration.cc says why).
  void RoundCovariance();

  std::string serial_;
  Family family_;
  std::vector<double> params_, covariance_;
  // A spline family's surfaces at params_, set up once (flux_family.h):
  // the tables evaluate a calibration ~10^5 times per table.
  SplineSurface spline_;
  int pole_pairs_ = 0;   // 0: unknown (only a default-constructed calibration)
  std::optional<double> rs_ohm_, psi_pm_nominal_wb_, udc_v_;
  std::optional<double> psi_pm_temp_coeff_per_k_, magnet_reference_c_, magnet_reference_spread_k_;
  double id_min_a_ = 0, id_max_a_ = 0, iq_min_a_ = 0, iq_max_a_ = 0;
  IqHalves iq_halves_ = IqHalves::kUnknown;
  double iq_signed_min_a_ = 0, iq_signed_max_a_ = 0;
};

// A spread of the flux map's recorded temperatures beyond which the
// calibration's magnet reference is a mean over a warming machine rather
// than one temperature: said wherever the reference is used (report,
// exports at another magnet temperature), K.
inline constexpr double kMagnetReferenceSpreadWarnK = 10.0;

// The magnet temperature facts of a calibration as read (FromJson, the
// binary codec): the coefficient finite and within the manifest's range
// (io::kMinPsiPmTempCoeffPerK .. kMaxPsiPmTempCoeffPerK), the reference
// finite in -60 .. 250 degC, the spread finite, >= 0 and only with a
// reference. InvalidArgument naming the JSON field otherwise.
absl::Status CheckMagnetTemperatureFacts(const std::optional<double>& psi_pm_temp_coeff_per_k,
                                         const std::optional<double>& magnet_reference_c,
                                         const std::optional<double>& magnet_reference_spread_k);

absl::StatusOr<Calibration> LoadCalibrationFile(const std::string& path);
absl::Status SaveCalibrationFile(const std::string& path, const Calibration& cal);

}  // namespace fluxcal::fit

#endif  // FLUXCAL_FITTING_CALIBRATION_H_
