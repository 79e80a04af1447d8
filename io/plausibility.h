// Physical plausibility limits of what fluxcal accepts, in one place: the
// service checks every request against them (server/validation.cc) and the
// flux-map reader every map (io/flux_map_conform.cc), so a value the service
// refuses is refused from a file too, with the same bound in the message.
//
// The limits bound a traction or industrial PMSM generously (SI units):
// phase currents below 10 kA, speeds below 100 000 rpm, magnet flux linkage
// 0..10 Wb (and no flux linkage above that), differential self-inductances
// in [1e-7, 1) H, a stator resistance 0..10 ohm, winding temperature
// -60..250 degC, 1..100 pole pairs. A value outside them is a wrong unit or
// a wrong column far more often than a machine.
//
// Each Check* returns OK or InvalidArgument "<field>: <rule>, got <value>",
// e.g. "points[3].ld_h: must be in [1e-7, 1) H, got -0.0001"; a non-finite
// value gives "<field>: must be a finite number, got nan".
#ifndef FLUXCAL_IO_PLAUSIBILITY_H_
#define FLUXCAL_IO_PLAUSIBILITY_H_

#include <string_view>

#include "absl/status/status.h"

namespace fluxcal::io {

inline constexpr double kMaxAbsCurrentA = 1e4;         // |id|, |iq|, current limits
inline constexpr double kMaxAbsSpeedRpm = 1e5;
inline constexpr double kMaxFluxLinkageWb = 10.0;      // psi_pm, and |psi| anywhere
inline constexpr double kMinInductanceH = 1e-7;        // differential self-inductance,
inline constexpr double kMaxInductanceH = 1.0;         //   in [min, max)
inline constexpr double kMaxAbsCrossInductanceH = 1.0; // |ldq|
inline constexpr double kMaxRsOhm = 10.0;
inline constexpr double kMinTemperatureC = -60.0;
inline constexpr double kMaxTemperatureC = 250.0;
inline constexpr int kMaxPolePairs = 100;

// |v| <= kMaxAbsCurrentA: "must be within +-10 kA".
absl::Status CheckCurrentA(std::string_view field, double v);
// |v| <= kMaxAbsSpeedRpm: "must be within +-100000 rpm".
absl::Status CheckSpeedRpm(std::string_view field, double v);
// 0 <= v <= kMaxFluxLinkageWb: "must be 0..10 Wb".
absl::Status CheckPsiPmWb(std::string_view field, double v);
// kMinInductanceH <= v < kMaxInductanceH: "must be in [1e-7, 1) H".
absl::Status CheckInductanceH(std::string_view field, double v);
// An HF injection's flux-circle radius: 0 < v <= kMaxFluxLinkageWb,
// "must be in (0, 10] Wb".
absl::Status CheckHfFluxRadiusWb(std::string_view field, double v);
// |v| <= kMaxAbsCrossInductanceH: "must be within +-1 H".
absl::Status CheckCrossInductanceH(std::string_view field, double v);
// A standard deviation of an inductance, 0..kMaxInductanceH: "must be 0..1 H".
absl::Status CheckInductanceStdH(std::string_view field, double v);
// 0 <= v <= kMaxRsOhm: "must be 0..10 Ohm".
absl::Status CheckRsOhm(std::string_view field, double v);
// kMinTemperatureC..kMaxTemperatureC: "must be -60..250 degC".
absl::Status CheckTemperatureC(std::string_view field, double v);
// 1..kMaxPolePairs: "must be 1..100".
absl::Status CheckPolePairs(std::string_view field, int v);

}  // namespace fluxcal::io

#endif  // FLUXCAL_IO_PLAUSIBILITY_H_
