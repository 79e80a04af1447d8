// Validation of every incoming message, in one place. Messages name the
// field and the point, e.g. "points[3].ld_h: must be positive and below 1 H,
// got -0.0001". Returns InvalidArgument.
#ifndef FLUXCAL_SERVER_VALIDATION_H_
#define FLUXCAL_SERVER_VALIDATION_H_

#include <string>

#include "absl/status/status.h"
#include "fluxcal/v1/calibration.pb.h"

namespace fluxcal::server {

inline constexpr int kMaxPointsPerStream = 100000;
// A recording set as uploaded: at most this many bytes over all files and
// this many files (a 1000-point set at 10 kHz for 0.2 s a point is ~25 MB in
// ~1000 files).
inline constexpr long long kMaxRecordingBytes = 256LL << 20;
inline constexpr int kMaxRecordingFiles = 4096;
// Free-text identifiers (station_id, point_id): printable ASCII only.
inline constexpr size_t kMaxIdentifierBytes = 64;

absl::Status ValidateSerial(const std::string& serial, const std::string& field = "serial");
// station_id / point_id: at most kMaxIdentifierBytes of printable ASCII
// (0x20..0x7e); empty allowed when `required` is false.
absl::Status ValidateIdentifier(const std::string& value, const std::string& field, bool required = false);
absl::Status ValidateMotor(const fluxcal::v1::MotorInfo& m);
// `index` is the point's position in the stream.
absl::Status ValidatePoint(const fluxcal::v1::HfPoint& p, int index);
absl::Status ValidateOperatingPoint(const fluxcal::v1::OperatingPoint& p, int index);

}  // namespace fluxcal::server

#endif  // FLUXCAL_SERVER_VALIDATION_H_
