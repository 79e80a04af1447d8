#include "server/validation.h"

#include <cmath>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "io/csv.h"
#include "io/plausibility.h"
#include "io/recording_set.h"

namespace fluxcal::server {
namespace {

// The physical plausibility limits (currents, speeds, flux linkage,
// inductances, resistance, temperature, pole pairs) live in
// io/plausibility.h, shared with the flux-map reader; only the bounds of
// what a request may ask for are here.
absl::Status Range(const std::string& field, double v, double lo, double hi, const std::string& what) {
  if (!std::isfinite(v) || v < lo || v > hi) {
    return absl::InvalidArgumentError(
        absl::StrFormat("%s: %s, got %.9g", field, std::isfinite(v) ? what : "must be a finite number", v));
  }
  return absl::OkStatus();
}

}  // namespace

absl::Status ValidateSerial(const std::string& serial, const std::string& field) {
  if (serial.empty()) return absl::InvalidArgumentError(absl::StrCat(field, ": must not be empty"));
  if (!io::IsValidSerial(serial)) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ": illegal serial '", io::Printable(serial.substr(0, 80)), "' (1 to 64 characters of A-Z a-z 0-9 - _ .)"));
  }
  return absl::OkStatus();
}

absl::Status ValidateIdentifier(const std::string& value, const std::string& field, bool required) {
  if (value.empty()) {
    if (required) return absl::InvalidArgumentError(absl::StrCat(field, ": must not be empty"));
    return absl::OkStatus();
  }
  if (value.size() > kMaxIdentifierBytes) {
    return absl::InvalidArgumentError(
        absl::StrCat(field, ": longer than ", kMaxIdentifierBytes, " bytes (", value.size(), ")"));
  }
  for (unsigned char c : value) {
    if (c < 0x20 || c > 0x7e) {
      return absl::InvalidArgumentError(absl::StrCat(
          field, ": only printable ASCII is allowed, got byte 0x", absl::Hex(c, absl::kZeroPad2)));
    }
  }
  return absl::OkStatus();
}

absl::Status ValidateMotor(const fluxcal::v1::MotorInfo& m) {
  if (auto s = io::CheckPolePairs("motor.pole_pairs", m.pole_pairs()); !s.ok()) return s;
  if (auto s = io::CheckRsOhm("motor.rs_ohm", m.rs_ohm()); !s.ok()) return s;
  return io::CheckPsiPmWb("motor.psi_pm_wb", m.psi_pm_wb());
}

absl::Status ValidatePoint(const fluxcal::v1::HfPoint& p, int i) {
  const std::string f = absl::StrCat("points[", i, "]");
  if (auto s = ValidateIdentifier(p.point_id(), f + ".point_id"); !s.ok()) return s;
  if (auto s = io::CheckCurrentA(f + ".id_a", p.id_a()); !s.ok()) return s;
  if (auto s = io::CheckCurrentA(f + ".iq_a", p.iq_a()); !s.ok()) return s;
  if (auto s = io::CheckSpeedRpm(f + ".speed_rpm", p.speed_rpm()); !s.ok()) return s;
  if (auto s = io::CheckInductanceH(f + ".ld_h", p.ld_h()); !s.ok()) return s;
  if (auto s = io::CheckInductanceH(f + ".lq_h", p.lq_h()); !s.ok()) return s;
  if (p.has_ldq_h()) {
    if (auto s = io::CheckCrossInductanceH(f + ".ldq_h", p.ldq_h()); !s.ok()) return s;
  }
  for (auto [name, v] : {std::pair<const char*, double>{".ld_h_std", p.ld_h_std()},
                         {".lq_h_std", p.lq_h_std()}, {".ldq_h_std", p.ldq_h_std()}}) {
    if (auto s = io::CheckInductanceStdH(f + name, v); !s.ok()) return s;
  }
  // A standard error as large as the value says the point carries no
  // information; such a point is refused, not fitted.
  if (p.ld_h_std() >= p.ld_h()) {
    return absl::InvalidArgumentError(absl::StrFormat("%s.ld_h_std: must be below ld_h, got %.9g", f, p.ld_h_std()));
  }
  if (p.lq_h_std() >= p.lq_h()) {
    return absl::InvalidArgumentError(absl::StrFormat("%s.lq_h_std: must be below lq_h, got %.9g", f, p.lq_h_std()));
  }
  if (p.has_hf_flux_radius_wb()) {
    if (auto s = io::CheckHfFluxRadiusWb(f + ".hf_flux_radius_wb", p.hf_flux_radius_wb()); !s.ok()) return s;
  }
  return io::CheckTemperatureC(f + ".temperature_c", p.temperature_c());
}

absl::Status ValidateOperatingPoint(const fluxcal::v1::OperatingPoint& p, int i) {
  const std::string f = absl::StrCat("points[", i, "]");
  if (auto s = io::CheckCurrentA(f + ".id_a", p.id_a()); !s.ok()) return s;
  return io::CheckCurrentA(f + ".iq_a", p.iq_a());
}

absl::Status ValidateStreamEnd(const fluxcal::v1::StreamEnd& e, const std::string& field) {
  if (e.messages() < 1) return absl::InvalidArgumentError(absl::StrCat(field, ".messages: must be >= 1, got ", e.messages()));
  if (e.count() < 0) return absl::InvalidArgumentError(absl::StrCat(field, ".count: must be >= 0, got ", e.count()));
  if (e.bytes() < 0) return absl::InvalidArgumentError(absl::StrCat(field, ".bytes: must be >= 0, got ", e.bytes()));
  bool hex = e.sha256().size() == 64;
  for (char c : e.sha256()) hex = hex && ((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'));
  if (!hex) {
    return absl::InvalidArgumentError(absl::StrCat(field, ".sha256: must be 64 lower-case hex digits, got '",
                                                   io::Printable(e.sha256().substr(0, 80)), "'"));
  }
  return absl::OkStatus();
}

absl::Status ValidateVersion(int version) {
  if (version < 0) return absl::InvalidArgumentError(absl::StrCat("version: must be >= 0 (0 = latest), got ", version));
  return absl::OkStatus();
}

absl::Status ValidateDefaultable(const std::string& field, double value, double max, const std::string& unit) {
  if (value == 0) return absl::OkStatus();
  return Range(field, value, std::nextafter(0.0, 1.0), max,
               absl::StrFormat("must be in (0, %g] %s (0: default)", max, unit));
}

absl::Status ValidateUdcAxis(const google::protobuf::RepeatedField<double>& axis, double udc_v, int max_points) {
  if (axis.empty()) return absl::OkStatus();
  if (axis.size() > max_points) {
    return absl::InvalidArgumentError(
        absl::StrFormat("udc_axis_v: at most %d voltages (one table each), got %d", max_points, axis.size()));
  }
  if (udc_v != 0) {
    return absl::InvalidArgumentError("udc_v: give one Udc or a Udc axis (udc_axis_v), not both");
  }
  for (int k = 0; k < axis.size(); ++k) {
    if (auto s = Range(absl::StrCat("udc_axis_v[", k, "]"), axis.Get(k), std::nextafter(0.0, 1.0), kMaxUdcV,
                       absl::StrFormat("must be in (0, %g] V", kMaxUdcV));
        !s.ok()) {
      return s;
    }
  }
  return absl::OkStatus();
}

absl::StatusOr<int> ParsePageToken(const std::string& token) {
  int offset = 0;
  if (token.empty()) return 0;
  if (token.size() > 10 || !absl::SimpleAtoi(token, &offset) || offset < 0 ||
      token.find_first_not_of("0123456789") != std::string::npos) {
    return absl::InvalidArgumentError("page_token: not a token from this service");
  }
  return offset;
}

}  // namespace fluxcal::server
