// Validation of every incoming message, in one place. Messages name the
// field and the point, e.g. "points[3].ld_h: must be positive and below 1 H,
// got -0.0001". Returns InvalidArgument.
#ifndef FLUXCAL_SERVER_VALIDATION_H_
#define FLUXCAL_SERVER_VALIDATION_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "fluxcal/v1/calibration.pb.h"

namespace fluxcal::server {

// One run: a dense EOL grid is ~1000 points; 10 000 bounds the fit's cost
// (a few seconds, docs/performance.md) instead of letting one request take
// minutes and gigabytes.
inline constexpr int kMaxPointsPerStream = 10000;
// The fewest distinct operating points a run needs is pipeline's
// (pipeline::kMinDistinctOperatingPoints, CheckDistinctOperatingPoints).
// Batch queries and fleet statistics.
inline constexpr int kMaxQueryPoints = 100000;
inline constexpr int kMaxFleetPoints = 1000;
// Table grids: rows per curve, and cells of a field-weakening map.
inline constexpr int kMaxTablePoints = 1024;
inline constexpr int kMaxTableSpeedPoints = 256;
inline constexpr long long kMaxTableCells = 65536;
// Longest message a client gets back (values inside are already escaped
// and cut); gRPC metadata limits are a few kB.
inline constexpr size_t kMaxStatusMessageBytes = 1024;
// The physical plausibility limits (inductance, current, flux linkage, ...)
// are io/plausibility.h, shared with the flux-map reader.
// A recording set as uploaded: at most this many bytes over all files and
// this many files (a 1000-point set at 10 kHz for 0.2 s a point is ~25 MB in
// ~1000 files).
inline constexpr long long kMaxRecordingBytes = 256LL << 20;
inline constexpr int kMaxRecordingFiles = 4096;
// Free-text identifiers (station_id, point_id): printable ASCII only.
inline constexpr size_t kMaxIdentifierBytes = 64;
// Operating conditions a request may name (GetReport): the speed bound of
// every other speed field, the DC-link bound of ExportTable.
inline constexpr double kMaxSpeedRpm = 1e5;
inline constexpr double kMaxUdcV = 5000;
// A report page is ~0.5 MB; the bound keeps a reply under gRPC's default
// 4 MiB receive limit, so a client with default settings (grpcio,
// grpcurl) can take every page this service sends.
inline constexpr size_t kMaxReportBytes = 4000000;

absl::Status ValidateSerial(const std::string& serial, const std::string& field = "serial");
// station_id / point_id: at most kMaxIdentifierBytes of printable ASCII
// (0x20..0x7e); empty allowed when `required` is false.
absl::Status ValidateIdentifier(const std::string& value, const std::string& field, bool required = false);
absl::Status ValidateMotor(const fluxcal::v1::MotorInfo& m);
// `index` is the point's position in the stream.
absl::Status ValidatePoint(const fluxcal::v1::HfPoint& p, int index);
absl::Status ValidateOperatingPoint(const fluxcal::v1::OperatingPoint& p, int index);
// The declared end of an ingest stream: counts >= 0, messages >= 1,
// sha256 64 lower-case hex digits; `field` names it ("end", "chunks[9].end").
absl::Status ValidateStreamEnd(const fluxcal::v1::StreamEnd& end, const std::string& field);
// version: 0 = latest, n > 0 = that version; negative is refused.
absl::Status ValidateVersion(int version);
// An optional quantity where 0 means "the default": 0, or finite in
// (0, max]; the message names field, range and unit.
absl::Status ValidateDefaultable(const std::string& field, double value, double max, const std::string& unit);
// ExportTable's udc_axis_v: at most `max_points` voltages (InvalidArgument
// naming udc_axis_v and the count), each finite in (0, kMaxUdcV] V
// (naming udc_axis_v[k]), not with a nonzero udc_v (naming both).
absl::Status ValidateUdcAxis(const google::protobuf::RepeatedField<double>& axis, double udc_v, int max_points);
// A page token this service issued: a non-negative decimal offset.
absl::StatusOr<int> ParsePageToken(const std::string& token);

}  // namespace fluxcal::server

#endif  // FLUXCAL_SERVER_VALIDATION_H_
