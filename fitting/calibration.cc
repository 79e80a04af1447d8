#include "fitting/calibration.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <sstream>

#include <Eigen/Dense>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include "physics/torque.h"

namespace fluxcal::fit {

Calibration::Calibration(std::string serial, Family family, std::vector<double> params,
                         std::vector<double> covariance, int pole_pairs, std::optional<double> rs_ohm,
                         double id_min_a, double id_max_a, double iq_min_a, double iq_max_a)
    : serial_(std::move(serial)), family_(family), params_(std::move(params)),
      covariance_(std::move(covariance)), pole_pairs_(pole_pairs), rs_ohm_(rs_ohm),
      id_min_a_(id_min_a), id_max_a_(id_max_a), iq_min_a_(iq_min_a), iq_max_a_(iq_max_a) {
  RoundCovariance();
  if (family_.kind == Family::kSpline && static_cast<int>(params_.size()) == family_.NumParams()) {
    spline_ = SplineSurface(family_.spline, params_.data());
  }
}

void Calibration::RoundCovariance() {
  // The covariance is kept symmetric and at float precision (24-bit
  // significand, ~7 significant digits): it only ever becomes standard
  // deviations (Predict), and an uncertainty is not known to more than a
  // few digits, so nothing is lost; what is gained is that the stored
  // binary form (its upper triangle as float32, pipeline/calibration_codec.h)
  // holds the calibration exactly, and JSON -> binary -> JSON reads back
  // bit for bit. The fit and FromJson both construct through here: the one
  // place this happens. Symmetric: the mean of (r, c) and (c, r), which is
  // either of them when they agree; beyond the float range: +-inf.
  const size_t n = params_.size();
  if (covariance_.size() != n * n) return;
  for (size_t r = 0; r < n; ++r) {
    for (size_t c = r; c < n; ++c) {
      const double m = 0.5 * (covariance_[r * n + c] + covariance_[c * n + r]);
      const double f = std::abs(m) > std::numeric_limits<float>::max()
                           ? std::copysign(std::numeric_limits<double>::infinity(), m)
                           : static_cast<double>(static_cast<float>(m));
      covariance_[r * n + c] = covariance_[c * n + r] = f;
    }
  }
}

sim::FluxLinkage Calibration::Flux(double id, double iq, double) const {
  sim::FluxLinkage f;
  if (!spline_.empty()) {
    spline_.Eval(id, iq, &f.psi_d_wb, &f.psi_q_wb, nullptr, nullptr, nullptr);
  } else {
    FamilyFlux(family_, id, iq, params_.data(), &f.psi_d_wb, &f.psi_q_wb);
  }
  return f;
}

sim::DifferentialInductance Calibration::Inductance(double id, double iq, double) const {
  sim::DifferentialInductance l;
  if (!spline_.empty()) {
    spline_.Eval(id, iq, nullptr, nullptr, &l.ldd_h, &l.lqq_h, &l.ldq_h);
  } else {
    FamilyInductance(family_, id, iq, params_.data(), &l.ldd_h, &l.lqq_h, &l.ldq_h);
  }
  return l;
}

void Calibration::FluxAndInductance(double id, double iq, double temperature_c, sim::FluxLinkage* f,
                                    sim::DifferentialInductance* l) const {
  if (spline_.empty()) {
    if (family_.kind == Family::kAnalytic) {
      // One pass for both (the same values as Flux and Inductance).
      sim::SaturationFluxAndInductance(id, iq, params_.data(), &f->psi_d_wb, &f->psi_q_wb, &l->ldd_h, &l->lqq_h,
                                       &l->ldq_h);
      return;
    }
    *f = Flux(id, iq, temperature_c);
    *l = Inductance(id, iq, temperature_c);
    return;
  }
  spline_.Eval(id, iq, &f->psi_d_wb, &f->psi_q_wb, &l->ldd_h, &l->lqq_h, &l->ldq_h);
}

const char* RegionName(Region r) {
  switch (r) {
    case Region::kMeasured: return "measured";
    case Region::kBySymmetry: return "by_symmetry";
    case Region::kExtrapolated: return "extrapolated";
  }
  return "extrapolated";
}

const char* IqHalvesName(IqHalves h) {
  switch (h) {
    case IqHalves::kUnknown: return "unknown";
    case IqHalves::kPositive: return "positive";
    case IqHalves::kNegative: return "negative";
    case IqHalves::kBoth: return "both";
  }
  return "unknown";
}

std::string NotPositiveDefiniteReason(double ldd, double lqq, double ldq) {
  // Sylvester's criterion: a symmetric 2 x 2 matrix is positive definite
  // iff its leading principal minors Ldd and Ldd Lqq - Ldq^2 are positive
  // (then Lqq > 0 follows; tested anyway, to name it).
  if (!(ldd > 0)) return absl::StrFormat("ldd_h = %.6g H is not positive", ldd);
  if (!(lqq > 0)) return absl::StrFormat("lqq_h = %.6g H is not positive", lqq);
  const double det = ldd * lqq - ldq * ldq;
  if (!(det > 0)) {
    return absl::StrFormat("det = ldd_h lqq_h - ldq_h^2 = %.6g H^2 is not positive (ldq_h = %.6g H)", det, ldq);
  }
  return "";
}

void Calibration::SetMeasuredIq(IqHalves halves, double iq_signed_min_a, double iq_signed_max_a) {
  iq_halves_ = halves;
  iq_signed_min_a_ = iq_signed_min_a;
  iq_signed_max_a_ = iq_signed_max_a;
}

Region Calibration::RegionOf(double id, double iq) const {
  // Measured region: the box spanned by the data, with 2 % margin.
  const double mi = 0.02 * (id_max_a_ - id_min_a_ + 1.0), mq = 0.02 * (iq_max_a_ - iq_min_a_ + 1.0);
  if (!(id >= id_min_a_ - mi && id <= id_max_a_ + mi)) return Region::kExtrapolated;
  if (iq_halves_ == IqHalves::kUnknown) {
    // As before the halves were recorded: the |iq| range mirrored to iq < 0
    // by the machine's symmetry psi(id, -iq) = (psi_d, -psi_q), all of it
    // "measured" (a signed range, iq_min_a < 0, is taken as it stands).
    const double aq = iq_min_a_ >= 0 ? std::abs(iq) : iq;
    return aq >= iq_min_a_ - mq && aq <= iq_max_a_ + mq ? Region::kMeasured : Region::kExtrapolated;
  }
  const double aq = std::abs(iq);
  if (!(aq >= iq_min_a_ - mq && aq <= iq_max_a_ + mq)) return Region::kExtrapolated;
  auto on_measured_half = [&](double q) { return q >= iq_signed_min_a_ - mq && q <= iq_signed_max_a_ + mq; };
  if (on_measured_half(iq)) return Region::kMeasured;
  // The other half: for a model symmetric in iq it is the measured half
  // mirrored; a model that is not symmetric says there what nothing
  // measured.
  if (family_.SymmetricInIq() && on_measured_half(-iq)) return Region::kBySymmetry;
  return Region::kExtrapolated;
}

std::string Calibration::MagnetTemperatureText() const {
  std::string s;
  if (psi_pm_temp_coeff_per_k_) {
    s = absl::StrFormat("psi_pm changes by %.4g %%/K of magnet temperature (stated)", 100 * *psi_pm_temp_coeff_per_k_);
  } else {
    s = "no psi_pm temperature coefficient stated";
  }
  if (magnet_reference_c_) {
    absl::StrAppendFormat(&s, "; flux map at %.4g degC", *magnet_reference_c_);
    if (magnet_reference_spread_k_ && *magnet_reference_spread_k_ > 0) {
      absl::StrAppendFormat(&s, " (mean of the recorded temperatures, spread %.3g K%s)", *magnet_reference_spread_k_,
                            *magnet_reference_spread_k_ > kMagnetReferenceSpreadWarnK
                                ? absl::StrFormat(", more than %.3g K: a machine warming during the test, its psi_pm "
                                                  "is that of a mean temperature", kMagnetReferenceSpreadWarnK)
                                : "");
    }
  } else {
    s += "; no magnet temperature recorded for its flux map";
  }
  return s;
}

std::string Calibration::IqRegionText() const {
  if (iq_halves_ == IqHalves::kUnknown) {
    return absl::StrFormat("|iq| %.4g .. %.4g A, both halves counted as measured (the calibration does not record "
                           "which half the data measured)", iq_min_a_, iq_max_a_);
  }
  const std::string measured = absl::StrFormat("iq %.4g .. %.4g A measured", iq_signed_min_a_ + 0.0, iq_signed_max_a_ + 0.0);
  if (iq_halves_ == IqHalves::kBoth) return measured + " (both halves)";
  const bool pos = iq_halves_ == IqHalves::kPositive;
  // The other half as a range, or "iq < 0" / "iq > 0" when not mirrored.
  const std::string other = absl::StrFormat("iq %.4g .. %.4g A", pos ? -iq_signed_max_a_ : -iq_signed_min_a_ + 0.0,
                                            pos ? -iq_signed_min_a_ + 0.0 : -iq_signed_max_a_);
  if (family_.SymmetricInIq()) {
    return absl::StrCat(measured, "; ", other,
                        " by symmetry (the measured half mirrored: psi_d even, psi_q odd in iq; not measured)");
  }
  return absl::StrCat(measured, "; ", pos ? "iq < 0" : "iq > 0", " extrapolated (model ", family_.Name(),
                      " is not symmetric in iq, and the data measured one half)");
}

bool Calibration::InMeasuredRegion(double id, double iq) const { return RegionOf(id, iq) != Region::kExtrapolated; }

bool Calibration::PhysicalOver(double factor, const std::vector<Box>& except) const {
  const double lo = std::min(id_min_a_, 0.0) * factor, hi = std::max(id_max_a_, 0.0);
  // iq range checked: |iq| up to the measured maximum for a symmetric model
  // (the inductance of the other half is the mirror image: Ldd, Lqq even,
  // Ldq odd, the same determinant); the signed range measured otherwise.
  double q_lo = 0, q_hi = std::max(iq_max_a_, 1.0) * factor;
  if (!family_.SymmetricInIq() && iq_halves_ != IqHalves::kUnknown) {
    q_lo = iq_halves_ == IqHalves::kPositive ? 0.0 : std::min(iq_signed_min_a_, -1.0) * factor;
    q_hi = iq_halves_ == IqHalves::kNegative ? 0.0 : std::max(iq_signed_max_a_, 1.0) * factor;
  }
  const int nq = q_lo < 0 && q_hi > 0 ? 24 : 12;   // the same node spacing on each measured half
  for (int a = 0; a <= 12; ++a) {
    const double id = lo + (hi - lo) * a / 12;
    for (int b = 0; b <= nq; ++b) {
      const double iq = q_lo + (q_hi - q_lo) * b / nq;
      const bool excepted = std::any_of(except.begin(), except.end(), [&](const Box& x) {
        return id >= x.id_lo_a && id <= x.id_hi_a && std::abs(iq) >= x.abs_iq_lo_a && std::abs(iq) <= x.abs_iq_hi_a;
      });
      if (excepted) continue;
      const auto L = Inductance(id, iq);
      if (!NotPositiveDefiniteReason(L.ldd_h, L.lqq_h, L.ldq_h).empty()) return false;
    }
  }
  return true;
}

double Calibration::MeasuredCurrentLimitA() const {
  return std::min(std::abs(std::min(id_min_a_, 0.0)), iq_max_a_);
}

FluxPrediction Calibration::Predict(double id, double iq) const {
  // Outputs y(p) = (psi_d, psi_q, Ldd, Lqq, Ldq, Ld_app, Lq_app, T).
  auto eval = [&](const std::vector<double>& p, double* y) {
    double pd, pq, a, b, c;
    FamilyFlux(family_, id, iq, p.data(), &pd, &pq);
    FamilyInductance(family_, id, iq, p.data(), &a, &b, &c);
    y[0] = pd; y[1] = pq; y[2] = a; y[3] = b; y[4] = c;
    y[5] = std::abs(id) > 1e-9 ? (pd - p[0]) / id : a;
    y[6] = std::abs(iq) > 1e-9 ? pq / iq : b;
    y[7] = physics::ElectromagneticTorque(pole_pairs_, pd, pq, id, iq);
  };
  double y[8];
  eval(params_, y);
  FluxPrediction out;
  out.psi_d_wb = y[0]; out.psi_q_wb = y[1]; out.ldd_h = y[2]; out.lqq_h = y[3]; out.ldq_h = y[4];
  out.ld_app_h = y[5]; out.lq_app_h = y[6]; out.torque_nm = y[7];
  out.region = RegionOf(id, iq);
  out.extrapolated = out.region == Region::kExtrapolated;
  out.invalid_reason = NotPositiveDefiniteReason(out.ldd_h, out.lqq_h, out.ldq_h);
  out.valid = out.invalid_reason.empty();
  const size_t n = params_.size();
  if (covariance_.size() == n * n) {
    Eigen::MatrixXd J(8, n);
    for (size_t k = 0; k < n; ++k) {
      std::vector<double> pp = params_, pm = params_;
      const double h = 1e-6 * std::max(std::abs(params_[k]), 1e-9);
      pp[k] += h; pm[k] -= h;
      double yp[8], ym[8];
      eval(pp, yp);
      eval(pm, ym);
      for (int r = 0; r < 8; ++r) J(r, k) = (yp[r] - ym[r]) / (2 * h);
    }
    const Eigen::Map<const Eigen::MatrixXd> C(covariance_.data(), n, n);
    const Eigen::MatrixXd V = J * C * J.transpose();
    auto sd = [&](int r) { return std::sqrt(std::max(0.0, V(r, r))); };
    out.psi_d_wb_std = sd(0); out.psi_q_wb_std = sd(1); out.ldd_h_std = sd(2);
    out.lqq_h_std = sd(3); out.ldq_h_std = sd(4); out.ld_app_h_std = sd(5);
    out.lq_app_h_std = sd(6); out.torque_nm_std = sd(7);
  }
  return out;
}

nlohmann::json Calibration::ToJson() const {
  nlohmann::json j;
  j["format"] = "fluxcal.calibration.v1";
  j["serial"] = serial_;
  j["version"] = version;
  j["model"] = family_.Name();
  if (family_.kind == Family::kSpline) {
    j["spline_knots"] = {{"id_lo_a", family_.spline.id_lo_a}, {"id_hi_a", family_.spline.id_hi_a},
                         {"iq_hi_a", family_.spline.iq_hi_a}};
    if (family_.spline.smoothing) {
      j["spline_knots"]["iq_lo_a"] = family_.spline.iq_lo_a;
      j["spline_knots"]["spans_id"] = family_.spline.spans;
      j["spline_knots"]["spans_iq"] = family_.spline.spans_q;
      // "smooth" written without it is the folded layout of older files.
      if (family_.spline.mirrored) j["spline_knots"]["mirrored"] = true;
    }
  }
  j["pole_pairs"] = pole_pairs_;
  // Facts as stated; an unknown one is left out (never written as 0).
  if (rs_ohm_) j["rs_ohm"] = *rs_ohm_;
  j["psi_pm_wb"] = psi_pm_wb();
  if (psi_pm_nominal_wb_) j["psi_pm_nominal_wb"] = *psi_pm_nominal_wb_;
  if (udc_v_) j["udc_v"] = *udc_v_;
  // Magnet temperature: a compatible extension of v1 (docs/fitting.md),
  // absent when not stated.
  if (psi_pm_temp_coeff_per_k_) j["psi_pm_temp_coeff_per_k"] = *psi_pm_temp_coeff_per_k_;
  if (magnet_reference_c_) j["magnet_reference_c"] = *magnet_reference_c_;
  if (magnet_reference_spread_k_) j["magnet_reference_spread_k"] = *magnet_reference_spread_k_;
  j["params"] = params_;
  j["covariance"] = covariance_;
  j["region"] = {{"id_min_a", id_min_a_}, {"id_max_a", id_max_a_},
                 {"iq_min_a", iq_min_a_}, {"iq_max_a", iq_max_a_}};
  if (iq_halves_ != IqHalves::kUnknown) {
    // A compatible extension of v1 (docs/fitting.md): readers that do not
    // know these fields ignore them; files without them load as before.
    j["region"]["iq_halves"] = IqHalvesName(iq_halves_);
    j["region"]["iq_signed_min_a"] = iq_signed_min_a_;
    j["region"]["iq_signed_max_a"] = iq_signed_max_a_;
  }
  j["fit"] = {{"observations", summary.observations}, {"chi2", summary.chi2}, {"bic", summary.bic},
              {"rms_relative", summary.rms_relative}, {"termination", summary.termination},
              {"usable", summary.usable}, {"candidates", summary.candidates},
              {"excluded", summary.excluded}};
  j["fit"]["effective_parameters"] = summary.effective_parameters;
  if (summary.smoothing_lambda > 0) j["fit"]["smoothing_lambda"] = summary.smoothing_lambda;
  // Written only when not isotropic: files of older versions (no field)
  // read back as 1, the penalty they were fitted with.
  if (summary.smoothing_anisotropy_q != 1.0) j["fit"]["smoothing_anisotropy_q"] = summary.smoothing_anisotropy_q;
  // Likewise only when not 0: older files read back as 0, the penalty
  // without the curvature term they were fitted with.
  if (summary.smoothing_curvature_weight != 0.0) {
    j["fit"]["smoothing_curvature_weight"] = summary.smoothing_curvature_weight;
  }
  if (summary.flux_nodes > 0) {
    auto& f = j["fit"];
    f["flux_nodes"] = summary.flux_nodes;
    f["flux_rms_relative"] = summary.flux_rms_relative;
    f["flux_max_relative"] = summary.flux_max_relative;
    f["flux_rms_wb"] = summary.flux_rms_wb;
    f["flux_max_wb"] = summary.flux_max_wb;
    f["flux_scale_wb"] = summary.flux_scale_wb;
  }
  return j;
}

absl::Status CheckMagnetTemperatureFacts(const std::optional<double>& coeff, const std::optional<double>& ref,
                                         const std::optional<double>& spread) {
  if (coeff && !(std::isfinite(*coeff) && *coeff >= io::kMinPsiPmTempCoeffPerK &&
                 *coeff <= io::kMaxPsiPmTempCoeffPerK)) {
    return absl::InvalidArgumentError(absl::StrFormat("field 'psi_pm_temp_coeff_per_k': expected %g .. %g per "
                                                      "kelvin, got %g", io::kMinPsiPmTempCoeffPerK,
                                                      io::kMaxPsiPmTempCoeffPerK, *coeff));
  }
  if (ref && !(std::isfinite(*ref) && *ref >= -60 && *ref <= 250)) {
    return absl::InvalidArgumentError(
        absl::StrFormat("field 'magnet_reference_c': expected -60 .. 250 degC, got %g", *ref));
  }
  if (spread && (!ref || !(std::isfinite(*spread) && *spread >= 0))) {
    return absl::InvalidArgumentError(absl::StrFormat(
        "field 'magnet_reference_spread_k': %s", ref ? absl::StrFormat("expected a finite number >= 0, got %g", *spread)
                                                     : std::string("given without magnet_reference_c")));
  }
  return absl::OkStatus();
}

namespace {

struct MagnetFacts {
  std::optional<double> coeff_per_k, reference_c, spread_k;
};

// The optional magnet temperature members of a calibration's JSON.
absl::StatusOr<MagnetFacts> MagnetFactsFromJson(const nlohmann::json& j) {
  MagnetFacts f;
  for (auto [key, dst] : {std::pair<const char*, std::optional<double>*>{"psi_pm_temp_coeff_per_k", &f.coeff_per_k},
                          {"magnet_reference_c", &f.reference_c},
                          {"magnet_reference_spread_k", &f.spread_k}}) {
    if (!j.contains(key) || j[key].is_null()) continue;
    if (!j[key].is_number()) return absl::InvalidArgumentError(absl::StrCat("field '", key, "': expected a number"));
    *dst = j[key].get<double>();
  }
  if (auto s = CheckMagnetTemperatureFacts(f.coeff_per_k, f.reference_c, f.spread_k); !s.ok()) return s;
  return f;
}

}  // namespace

absl::StatusOr<Calibration> Calibration::FromJson(const nlohmann::json& j) {
  try {
    if (j.value("format", "") != "fluxcal.calibration.v1") {
      return absl::InvalidArgumentError("field 'format': expected 'fluxcal.calibration.v1'");
    }
    Family fam;
    const std::string model = j.at("model").get<std::string>();
    if (model == "analytic") {
      fam.kind = Family::kAnalytic;
    } else if (model.rfind("poly", 0) == 0) {
      fam.kind = Family::kPoly;
      fam.degree = std::stoi(model.substr(4));
      if (fam.degree < 2 || fam.degree > 12) return absl::InvalidArgumentError("field 'model': bad degree");
    } else if (model == "smooth" || model == "smooth-asym") {
      fam.kind = Family::kSpline;
      fam.spline.smoothing = true;
      fam.spline.symmetric = model == "smooth";
      const auto& k = j.at("spline_knots");
      fam.spline.spans = k.at("spans_id").get<int>();
      fam.spline.spans_q = k.at("spans_iq").get<int>();
      fam.spline.id_lo_a = k.at("id_lo_a").get<double>();
      fam.spline.id_hi_a = k.at("id_hi_a").get<double>();
      fam.spline.iq_lo_a = k.at("iq_lo_a").get<double>();
      fam.spline.iq_hi_a = k.at("iq_hi_a").get<double>();
      fam.spline.mirrored = fam.spline.symmetric && k.value("mirrored", false);
      const bool folded = fam.spline.symmetric && !fam.spline.mirrored;
      if (fam.spline.spans < 1 || fam.spline.spans > 32 || fam.spline.spans_q < 1 || fam.spline.spans_q > 64 ||
          (folded && (fam.spline.spans_q % 2 != 0 || fam.spline.iq_lo_a != -fam.spline.iq_hi_a))) {
        return absl::InvalidArgumentError("field 'spline_knots': spans_id 1..32, spans_iq 1..64 (even and a "
                                          "symmetric range for 'smooth' without 'mirrored')");
      }
      if (!(fam.spline.id_hi_a > fam.spline.id_lo_a) || !(fam.spline.iq_hi_a > fam.spline.iq_lo_a)) {
        return absl::InvalidArgumentError("field 'spline_knots': empty knot range");
      }
      if (fam.spline.mirrored && !(fam.spline.iq_lo_a < 0 && fam.spline.iq_hi_a > 0)) {
        return absl::InvalidArgumentError("field 'spline_knots': a mirrored layout needs iq_lo_a < 0 < iq_hi_a");
      }
    } else if (model.rfind("spline", 0) == 0) {
      fam.kind = Family::kSpline;
      fam.spline.spans = std::stoi(model.substr(6));
      if (fam.spline.spans < 1 || fam.spline.spans > 8) {
        return absl::InvalidArgumentError("field 'model': spline spans must be 1..8");
      }
      const auto& k = j.at("spline_knots");
      fam.spline.id_lo_a = k.at("id_lo_a").get<double>();
      fam.spline.id_hi_a = k.at("id_hi_a").get<double>();
      fam.spline.iq_hi_a = k.at("iq_hi_a").get<double>();
      if (!(fam.spline.id_hi_a > fam.spline.id_lo_a) || !(fam.spline.iq_hi_a > 0)) {
        return absl::InvalidArgumentError("field 'spline_knots': empty knot range");
      }
    } else {
      return absl::InvalidArgumentError(absl::StrCat("field 'model': unknown model '", model, "'"));
    }
    auto params = j.at("params").get<std::vector<double>>();
    if (static_cast<int>(params.size()) != fam.NumParams()) {
      return absl::InvalidArgumentError(absl::StrCat("field 'params': expected ", fam.NumParams(),
                                                     " values for ", model, ", got ", params.size()));
    }
    auto cov = j.value("covariance", std::vector<double>{});
    if (!cov.empty() && cov.size() != params.size() * params.size()) {
      return absl::InvalidArgumentError("field 'covariance': wrong size");
    }
    const auto& r = j.at("region");
    const int pole_pairs = j.at("pole_pairs").get<int>();
    if (pole_pairs < 1 || pole_pairs > 100) {
      return absl::InvalidArgumentError(absl::StrCat("field 'pole_pairs': expected 1..100, got ", pole_pairs));
    }
    // An optional fact: absent or null is unknown. Files written before
    // the facts were optional wrote rs_ohm 0 for an Rs nobody stated (no
    // machine has Rs = 0): read as unknown.
    auto fact = [&](const char* key, bool zero_is_unknown) -> absl::StatusOr<std::optional<double>> {
      if (!j.contains(key) || j[key].is_null()) return std::optional<double>();
      const double v = j[key].get<double>();
      if (zero_is_unknown && v == 0.0) return std::optional<double>();
      if (!std::isfinite(v) || v < 0 || (v == 0.0 && std::string(key) == "udc_v")) {
        return absl::InvalidArgumentError(absl::StrCat("field '", key, "': expected a ",
                                                       std::string(key) == "udc_v" ? "positive" : "non-negative",
                                                       " number, got ", v));
      }
      return std::optional<double>(v);
    };
    auto rs = fact("rs_ohm", true);
    if (!rs.ok()) return rs.status();
    auto psi_nom = fact("psi_pm_nominal_wb", false);
    if (!psi_nom.ok()) return psi_nom.status();
    auto udc = fact("udc_v", false);
    if (!udc.ok()) return udc.status();
    Calibration c(j.at("serial").get<std::string>(), fam, params, cov, pole_pairs, *rs, r.at("id_min_a").get<double>(),
                  r.at("id_max_a").get<double>(), r.at("iq_min_a").get<double>(),
                  r.at("iq_max_a").get<double>());
    c.psi_pm_nominal_wb_ = *psi_nom;
    c.udc_v_ = *udc;
    auto magnet = MagnetFactsFromJson(j);
    if (!magnet.ok()) return magnet.status();
    c.psi_pm_temp_coeff_per_k_ = magnet->coeff_per_k;
    c.set_magnet_reference(magnet->reference_c, magnet->spread_k);
    if (r.contains("iq_halves")) {
      const std::string h = r.at("iq_halves").get<std::string>();
      IqHalves halves = IqHalves::kUnknown;
      for (IqHalves x : {IqHalves::kPositive, IqHalves::kNegative, IqHalves::kBoth}) {
        if (h == IqHalvesName(x)) halves = x;
      }
      if (halves == IqHalves::kUnknown) {
        return absl::InvalidArgumentError(absl::StrCat("field 'region.iq_halves': expected positive, negative or both, got '", h, "'"));
      }
      const double lo = r.at("iq_signed_min_a").get<double>(), hi = r.at("iq_signed_max_a").get<double>();
      if (!(lo <= hi) || (halves == IqHalves::kPositive && lo < 0) || (halves == IqHalves::kNegative && hi > 0)) {
        return absl::InvalidArgumentError(absl::StrFormat(
            "field 'region.iq_signed_min_a': [%g, %g] A does not fit iq_halves '%s'", lo, hi, h));
      }
      c.SetMeasuredIq(halves, lo, hi);
    }
    c.version = j.value("version", 0);
    if (j.contains("fit")) {
      const auto& f = j["fit"];
      c.summary.observations = f.value("observations", 0);
      c.summary.chi2 = f.value("chi2", 0.0);
      c.summary.bic = f.value("bic", 0.0);
      c.summary.rms_relative = f.value("rms_relative", 0.0);
      c.summary.termination = f.value("termination", "");
      c.summary.usable = f.value("usable", false);
      c.summary.candidates = f.value("candidates", std::vector<std::string>{});
      c.summary.excluded = f.value("excluded", std::vector<std::string>{});
      c.summary.effective_parameters = f.value("effective_parameters", 0.0);
      c.summary.smoothing_lambda = f.value("smoothing_lambda", 0.0);
      c.summary.smoothing_anisotropy_q = f.value("smoothing_anisotropy_q", 1.0);
      if (!(std::isfinite(c.summary.smoothing_anisotropy_q) && c.summary.smoothing_anisotropy_q > 0)) {
        return absl::InvalidArgumentError(absl::StrFormat(
            "field 'fit.smoothing_anisotropy_q': %g is not a positive finite number", c.summary.smoothing_anisotropy_q));
      }
      c.summary.smoothing_curvature_weight = f.value("smoothing_curvature_weight", 0.0);
      if (!(std::isfinite(c.summary.smoothing_curvature_weight) && c.summary.smoothing_curvature_weight >= 0)) {
        return absl::InvalidArgumentError(
            absl::StrFormat("field 'fit.smoothing_curvature_weight': %g is not a non-negative finite number",
                            c.summary.smoothing_curvature_weight));
      }
      // Absent before map fits reported them (and for fits without flux nodes).
      c.summary.flux_nodes = f.value("flux_nodes", 0);
      c.summary.flux_rms_relative = f.value("flux_rms_relative", 0.0);
      c.summary.flux_max_relative = f.value("flux_max_relative", 0.0);
      c.summary.flux_rms_wb = f.value("flux_rms_wb", 0.0);
      c.summary.flux_max_wb = f.value("flux_max_wb", 0.0);
      c.summary.flux_scale_wb = f.value("flux_scale_wb", 0.0);
    }
    return c;
  } catch (const nlohmann::json::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("calibration JSON: ", e.what()));
  } catch (const std::exception& e) {
    return absl::InvalidArgumentError(absl::StrCat("calibration JSON: ", e.what()));
  }
}

absl::StatusOr<Calibration> LoadCalibrationFile(const std::string& path) {
  auto text = io::ReadFileToString(path);
  if (!text.ok()) return text.status();
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(*text);
  } catch (const nlohmann::json::parse_error& e) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": ", e.what()));
  }
  auto c = Calibration::FromJson(j);
  if (!c.ok()) return absl::InvalidArgumentError(absl::StrCat(path, ": ", c.status().message()));
  return c;
}

absl::Status SaveCalibrationFile(const std::string& path, const Calibration& cal) {
  return io::WriteFileAtomically(path, cal.ToJson().dump(2) + "\n");
}

}  // namespace fluxcal::fit
