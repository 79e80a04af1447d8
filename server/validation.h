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
inline constexpr long long kMaxRecordingBytes = 512LL << 20;

absl::Status ValidateSerial(const std::string& serial, const std::string& field = "serial");
absl::Status ValidateMotor(const fluxcal::v1::MotorInfo& m);
// `index` is the point's position in the stream.
absl::Status ValidatePoint(const fluxcal::v1::HfPoint& p, int index);
absl::Status ValidateOperatingPoint(const fluxcal::v1::OperatingPoint& p, int index);

}  // namespace fluxcal::server

#endif  // FLUXCAL_SERVER_VALIDATION_H_
