#include "pipeline/calibration_codec.h"

#include <zlib.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <utility>
#include <vector>

#include "absl/strings/str_cat.h"
#include "fluxcal/v1/calibration_model.pb.h"

namespace fluxcal::pipeline {
namespace {

namespace v1 = ::fluxcal::v1;

void ToProto(const fit::Family& f, v1::ModelFamily* p) {
  switch (f.kind) {
    case fit::Family::kAnalytic: p->set_kind(v1::ModelFamily::ANALYTIC); break;
    case fit::Family::kPoly: p->set_kind(v1::ModelFamily::POLY); break;
    case fit::Family::kSpline: p->set_kind(v1::ModelFamily::SPLINE); break;
  }
  p->set_degree(f.degree);
  if (f.kind != fit::Family::kSpline) return;
  // Every field of the domain as it is, so the struct reads back identical
  // (spline<R> keeps the defaults of the fields it does not use).
  const fit::SplineDomain& s = f.spline;
  auto* k = p->mutable_spline();
  k->set_spans_id(s.spans);
  k->set_spans_iq(s.spans_q);
  k->set_id_lo_a(s.id_lo_a);
  k->set_id_hi_a(s.id_hi_a);
  k->set_iq_lo_a(s.iq_lo_a);
  k->set_iq_hi_a(s.iq_hi_a);
  k->set_smoothing(s.smoothing);
  k->set_symmetric(s.symmetric);
  k->set_mirrored(s.mirrored);
}

absl::StatusOr<fit::Family> FromProto(const v1::ModelFamily& p) {
  fit::Family f;
  switch (p.kind()) {
    case v1::ModelFamily::ANALYTIC: f.kind = fit::Family::kAnalytic; break;
    case v1::ModelFamily::POLY: f.kind = fit::Family::kPoly; break;
    case v1::ModelFamily::SPLINE: f.kind = fit::Family::kSpline; break;
    default: return absl::InvalidArgumentError(absl::StrCat("calibration model: unknown family kind ", p.kind()));
  }
  f.degree = p.degree();
  if (f.kind == fit::Family::kPoly && (f.degree < 2 || f.degree > 12)) {
    return absl::InvalidArgumentError(absl::StrCat("calibration model: poly degree ", f.degree, " is not 2..12"));
  }
  if (f.kind == fit::Family::kSpline) {
    const auto& k = p.spline();
    fit::SplineDomain& s = f.spline;
    s.spans = k.spans_id();
    s.spans_q = k.spans_iq();
    s.id_lo_a = k.id_lo_a();
    s.id_hi_a = k.id_hi_a();
    s.iq_lo_a = k.iq_lo_a();
    s.iq_hi_a = k.iq_hi_a();
    s.smoothing = k.smoothing();
    s.symmetric = k.symmetric();
    s.mirrored = k.mirrored();
    if (s.spans < 1 || s.spans > 32 || (s.smoothing && (s.spans_q < 1 || s.spans_q > 64)) ||
        !(s.id_hi_a > s.id_lo_a) || !(s.iq_hi_a > s.IqLo())) {
      return absl::InvalidArgumentError("calibration model: spline knots out of range");
    }
  }
  return f;
}

v1::MeasuredRegion::IqHalves ToProto(fit::IqHalves h) {
  switch (h) {
    case fit::IqHalves::kUnknown: return v1::MeasuredRegion::UNKNOWN;
    case fit::IqHalves::kPositive: return v1::MeasuredRegion::POSITIVE;
    case fit::IqHalves::kNegative: return v1::MeasuredRegion::NEGATIVE;
    case fit::IqHalves::kBoth: return v1::MeasuredRegion::BOTH;
  }
  return v1::MeasuredRegion::UNKNOWN;
}

fit::IqHalves FromProto(v1::MeasuredRegion::IqHalves h) {
  switch (h) {
    case v1::MeasuredRegion::POSITIVE: return fit::IqHalves::kPositive;
    case v1::MeasuredRegion::NEGATIVE: return fit::IqHalves::kNegative;
    case v1::MeasuredRegion::BOTH: return fit::IqHalves::kBoth;
    default: return fit::IqHalves::kUnknown;
  }
}

void ToProto(const fit::FitSummary& s, v1::FitSummary* p) {
  p->set_observations(s.observations);
  p->set_chi2(s.chi2);
  p->set_bic(s.bic);
  p->set_rms_relative(s.rms_relative);
  p->set_termination(s.termination);
  p->set_usable(s.usable);
  p->set_effective_parameters(s.effective_parameters);
  p->set_smoothing_lambda(s.smoothing_lambda);
  p->set_smoothing_anisotropy_q(s.smoothing_anisotropy_q);
  p->set_smoothing_curvature_weight(s.smoothing_curvature_weight);
  for (const auto& c : s.candidates) p->add_candidates(c);
  for (const auto& e : s.excluded) p->add_excluded(e);
  p->set_flux_nodes(s.flux_nodes);
  p->set_flux_rms_relative(s.flux_rms_relative);
  p->set_flux_max_relative(s.flux_max_relative);
  p->set_flux_rms_wb(s.flux_rms_wb);
  p->set_flux_max_wb(s.flux_max_wb);
  p->set_flux_scale_wb(s.flux_scale_wb);
}

fit::FitSummary FromProto(const v1::FitSummary& p) {
  fit::FitSummary s;
  s.observations = p.observations();
  s.chi2 = p.chi2();
  s.bic = p.bic();
  s.rms_relative = p.rms_relative();
  s.termination = p.termination();
  s.usable = p.usable();
  s.effective_parameters = p.effective_parameters();
  s.smoothing_lambda = p.smoothing_lambda();
  s.smoothing_anisotropy_q = p.smoothing_anisotropy_q();
  s.smoothing_curvature_weight = p.smoothing_curvature_weight();
  s.candidates.assign(p.candidates().begin(), p.candidates().end());
  s.excluded.assign(p.excluded().begin(), p.excluded().end());
  s.flux_nodes = p.flux_nodes();
  s.flux_rms_relative = p.flux_rms_relative();
  s.flux_max_relative = p.flux_max_relative();
  s.flux_rms_wb = p.flux_rms_wb();
  s.flux_max_wb = p.flux_max_wb();
  s.flux_scale_wb = p.flux_scale_wb();
  return s;
}

// The covariance's upper triangle as float32 (little-endian), byte-shuffled
// and deflated (calibration_model.proto says why). Deterministic: the same
// covariance gives the same bytes with the same zlib.
std::string PackCovariance(const std::vector<double>& cov, size_t n) {
  const size_t count = n * (n + 1) / 2;
  std::string shuffled(4 * count, '\0');
  size_t i = 0;
  for (size_t r = 0; r < n; ++r) {
    for (size_t c = r; c < n; ++c, ++i) {
      // Already a float value (Calibration::RoundCovariance): exact.
      const float f = static_cast<float>(cov[r * n + c]);
      uint32_t u;
      std::memcpy(&u, &f, sizeof u);
      for (size_t b = 0; b < 4; ++b) shuffled[b * count + i] = static_cast<char>((u >> (8 * b)) & 0xff);
    }
  }
  uLongf size = compressBound(shuffled.size());
  std::string out(size, '\0');
  if (compress2(reinterpret_cast<Bytef*>(out.data()), &size, reinterpret_cast<const Bytef*>(shuffled.data()),
                shuffled.size(), Z_BEST_COMPRESSION) != Z_OK) {
    std::abort();   // only on out-of-memory: the bound above always fits
  }
  out.resize(size);
  return out;
}

absl::StatusOr<std::vector<double>> UnpackCovariance(const std::string& packed, size_t n) {
  const size_t count = n * (n + 1) / 2;
  std::string shuffled(4 * count, '\0');
  uLongf size = shuffled.size();
  if (uncompress(reinterpret_cast<Bytef*>(shuffled.data()), &size, reinterpret_cast<const Bytef*>(packed.data()),
                 packed.size()) != Z_OK ||
      size != shuffled.size()) {
    return absl::InvalidArgumentError(absl::StrCat("calibration model: the covariance is not the packed upper "
                                                   "triangle of ", n, " x ", n, " (", count, " float32 values)"));
  }
  std::vector<double> cov(n * n);
  size_t i = 0;
  for (size_t r = 0; r < n; ++r) {
    for (size_t c = r; c < n; ++c, ++i) {
      uint32_t u = 0;
      for (size_t b = 0; b < 4; ++b) u |= static_cast<uint32_t>(static_cast<unsigned char>(shuffled[b * count + i])) << (8 * b);
      float f;
      std::memcpy(&f, &u, sizeof f);
      cov[r * n + c] = cov[c * n + r] = f;
    }
  }
  return cov;
}

absl::Status DataLoss(const storage::CalibrationRow& row, const absl::Status& why) {
  return absl::DataLossError(absl::StrCat("stored calibration of ", row.serial, " version ", row.version,
                                          " is corrupt: ", why.message()));
}

}  // namespace

std::string EncodeCalibration(const fit::Calibration& cal, const nlohmann::json& extra) {
  v1::CalibrationModel m;
  m.set_serial(cal.serial());
  m.set_version(cal.version);
  ToProto(cal.family(), m.mutable_family());
  m.set_pole_pairs(cal.pole_pairs());
  if (cal.rs_ohm()) m.set_rs_ohm(*cal.rs_ohm());
  if (cal.psi_pm_nominal_wb()) m.set_psi_pm_nominal_wb(*cal.psi_pm_nominal_wb());
  if (cal.udc_v()) m.set_udc_v(*cal.udc_v());
  if (cal.psi_pm_temp_coeff_per_k()) m.set_psi_pm_temp_coeff_per_k(*cal.psi_pm_temp_coeff_per_k());
  if (cal.magnet_reference_c()) m.set_magnet_reference_c(*cal.magnet_reference_c());
  if (cal.magnet_reference_spread_k()) m.set_magnet_reference_spread_k(*cal.magnet_reference_spread_k());
  m.mutable_params()->Add(cal.params().begin(), cal.params().end());
  const size_t n = cal.params().size();
  const auto& cov = cal.covariance();
  if (cov.size() == n * n) m.set_covariance_upper_f32_shuffled_zlib(PackCovariance(cov, n));
  auto* region = m.mutable_region();
  region->set_id_min_a(cal.id_min_a());
  region->set_id_max_a(cal.id_max_a());
  region->set_iq_min_a(cal.iq_min_a());
  region->set_iq_max_a(cal.iq_max_a());
  region->set_iq_halves(ToProto(cal.iq_halves()));
  region->set_iq_signed_min_a(cal.iq_signed_min_a());
  region->set_iq_signed_max_a(cal.iq_signed_max_a());
  ToProto(cal.summary, m.mutable_fit());
  if (extra.is_object() && !extra.empty()) m.set_extra_json(extra.dump());
  return m.SerializeAsString();
}

absl::StatusOr<fit::Calibration> DecodeCalibration(std::string_view bytes, nlohmann::json* extra) {
  v1::CalibrationModel m;
  if (!m.ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) {
    return absl::InvalidArgumentError("calibration model: not a fluxcal.v1.CalibrationModel");
  }
  auto family = FromProto(m.family());
  if (!family.ok()) return family.status();
  const size_t n = static_cast<size_t>(m.params_size());
  if (static_cast<int>(n) != family->NumParams()) {
    return absl::InvalidArgumentError(absl::StrCat("calibration model: ", n, " parameters, ", family->Name(),
                                                   " has ", family->NumParams()));
  }
  if (m.pole_pairs() < 1 || m.pole_pairs() > 100) {
    return absl::InvalidArgumentError(absl::StrCat("calibration model: pole_pairs ", m.pole_pairs(), " is not 1..100"));
  }
  std::vector<double> cov;
  if (!m.covariance_upper_f32_shuffled_zlib().empty()) {
    auto unpacked = UnpackCovariance(m.covariance_upper_f32_shuffled_zlib(), n);
    if (!unpacked.ok()) return unpacked.status();
    cov = std::move(*unpacked);
  }
  const auto& region = m.region();
  fit::Calibration cal(m.serial(), *family, std::vector<double>(m.params().begin(), m.params().end()),
                       std::move(cov), m.pole_pairs(),
                       m.has_rs_ohm() ? std::optional<double>(m.rs_ohm()) : std::nullopt, region.id_min_a(),
                       region.id_max_a(), region.iq_min_a(), region.iq_max_a());
  if (m.has_psi_pm_nominal_wb()) cal.set_psi_pm_nominal_wb(m.psi_pm_nominal_wb());
  if (m.has_udc_v()) cal.set_udc_v(m.udc_v());
  {
    auto opt = [](bool has, double v) { return has ? std::optional<double>(v) : std::nullopt; };
    const auto coeff = opt(m.has_psi_pm_temp_coeff_per_k(), m.psi_pm_temp_coeff_per_k());
    const auto ref = opt(m.has_magnet_reference_c(), m.magnet_reference_c());
    const auto spread = opt(m.has_magnet_reference_spread_k(), m.magnet_reference_spread_k());
    if (auto s = fit::CheckMagnetTemperatureFacts(coeff, ref, spread); !s.ok()) {
      return absl::InvalidArgumentError(absl::StrCat("calibration model: ", s.message()));
    }
    cal.set_psi_pm_temp_coeff_per_k(coeff);
    cal.set_magnet_reference(ref, spread);
  }
  const fit::IqHalves halves = FromProto(region.iq_halves());
  if (halves != fit::IqHalves::kUnknown) cal.SetMeasuredIq(halves, region.iq_signed_min_a(), region.iq_signed_max_a());
  cal.summary = FromProto(m.fit());
  cal.version = m.version();
  if (extra != nullptr) {
    *extra = nullptr;
    if (!m.extra_json().empty()) {
      *extra = nlohmann::json::parse(m.extra_json(), nullptr, false);
      if (extra->is_discarded() || !extra->is_object()) {
        return absl::InvalidArgumentError("calibration model: extra_json is not a JSON object");
      }
    }
  }
  return cal;
}

absl::StatusOr<std::string> CalibrationJsonToModel(const std::string& calibration_json) {
  nlohmann::json j = nlohmann::json::parse(calibration_json, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return absl::InvalidArgumentError("calibration JSON: not a JSON object");
  auto cal = fit::Calibration::FromJson(j);
  if (!cal.ok()) return cal.status();
  // What the calibration does not hold travels beside it.
  const nlohmann::json held = cal->ToJson();
  nlohmann::json extra = nlohmann::json::object();
  for (auto it = j.begin(); it != j.end(); ++it) {
    if (!held.contains(it.key())) extra[it.key()] = it.value();
  }
  return EncodeCalibration(*cal, extra);
}

absl::StatusOr<nlohmann::json> CalibrationModelToJson(std::string_view bytes) {
  nlohmann::json extra;
  auto cal = DecodeCalibration(bytes, &extra);
  if (!cal.ok()) return cal.status();
  nlohmann::json j = cal->ToJson();
  if (extra.is_object()) {
    for (auto it = extra.begin(); it != extra.end(); ++it) j[it.key()] = it.value();
  }
  return j;
}

absl::StatusOr<nlohmann::json> StoredCalibrationJson(const storage::CalibrationRow& row) {
  if (!row.model_pb.empty()) {
    auto j = CalibrationModelToJson(row.model_pb);
    if (!j.ok()) return DataLoss(row, j.status());
    return j;
  }
  nlohmann::json j = nlohmann::json::parse(row.calibration_json, nullptr, false);
  if (j.is_discarded() || !j.is_object()) return DataLoss(row, absl::InvalidArgumentError("not a JSON object"));
  return j;
}

absl::StatusOr<std::string> StoredCalibrationJsonText(const storage::CalibrationRow& row) {
  if (row.model_pb.empty()) return row.calibration_json;   // as stored, byte for byte
  auto j = StoredCalibrationJson(row);
  if (!j.ok()) return j.status();
  return j->dump();
}

}  // namespace fluxcal::pipeline
