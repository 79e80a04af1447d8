#include "io/plausibility.h"

#include <cmath>

#include "absl/strings/str_format.h"

namespace fluxcal::io {
namespace {

absl::Status Bad(std::string_view field, std::string_view what, double got) {
  return absl::InvalidArgumentError(absl::StrFormat("%s: %s, got %.9g", field, what, got));
}

// lo <= v <= hi (both closed).
absl::Status Range(std::string_view field, double v, double lo, double hi, std::string_view what) {
  if (!std::isfinite(v)) return Bad(field, "must be a finite number", v);
  if (v < lo || v > hi) return Bad(field, what, v);
  return absl::OkStatus();
}

}  // namespace

absl::Status CheckCurrentA(std::string_view field, double v) {
  return Range(field, v, -kMaxAbsCurrentA, kMaxAbsCurrentA, "must be within +-10 kA");
}

absl::Status CheckSpeedRpm(std::string_view field, double v) {
  return Range(field, v, -kMaxAbsSpeedRpm, kMaxAbsSpeedRpm, "must be within +-100000 rpm");
}

absl::Status CheckPsiPmWb(std::string_view field, double v) {
  return Range(field, v, 0, kMaxFluxLinkageWb, "must be 0..10 Wb");
}

absl::Status CheckInductanceH(std::string_view field, double v) {
  // Half-open: 1 H itself is out (a unit slip of mH -> H lands on it).
  if (!std::isfinite(v) || v < kMinInductanceH || v >= kMaxInductanceH) return Bad(field, "must be in [1e-7, 1) H", v);
  return absl::OkStatus();
}

absl::Status CheckHfFluxRadiusWb(std::string_view field, double v) {
  if (!std::isfinite(v) || v <= 0 || v > kMaxFluxLinkageWb) return Bad(field, "must be in (0, 10] Wb", v);
  return absl::OkStatus();
}

absl::Status CheckCrossInductanceH(std::string_view field, double v) {
  return Range(field, v, -kMaxAbsCrossInductanceH, kMaxAbsCrossInductanceH, "must be within +-1 H");
}

absl::Status CheckInductanceStdH(std::string_view field, double v) {
  return Range(field, v, 0, kMaxInductanceH, "must be 0..1 H");
}

absl::Status CheckRsOhm(std::string_view field, double v) { return Range(field, v, 0, kMaxRsOhm, "must be 0..10 Ohm"); }

absl::Status CheckTemperatureC(std::string_view field, double v) {
  return Range(field, v, kMinTemperatureC, kMaxTemperatureC, "must be -60..250 degC");
}

absl::Status CheckPolePairs(std::string_view field, int v) {
  if (v < 1 || v > kMaxPolePairs) return Bad(field, "must be 1..100", v);
  return absl::OkStatus();
}

}  // namespace fluxcal::io
