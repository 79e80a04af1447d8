// The stored form of a raw recording set (IngestRecording -> store ->
// Diagnose): named files in a RecordingArchive protobuf, zlib-compressed.
// Decoding checks every name again and never touches the filesystem, so a
// stored recording cannot make the service write a file.
#ifndef FLUXCAL_PIPELINE_RECORDING_ARCHIVE_H_
#define FLUXCAL_PIPELINE_RECORDING_ARCHIVE_H_

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"
#include "io/recording_set.h"

namespace fluxcal::pipeline {

// Largest archive a stored recording may expand to: an upload at the
// service's limit (256 MiB, server/validation.h) plus archive framing.
inline constexpr size_t kMaxStoredRecordingBytes = (size_t{256} << 20) + (size_t{64} << 20);

// Serialised archive (uncompressed): the magic line, then the protobuf.
std::string EncodeRecordingArchive(const io::RecordingFiles& files);

// Inverse of EncodeRecordingArchive. Also reads the first stored format
// ("name\nsize\nbytes" records) strictly: every name checked, sizes parsed
// without overflow, bounds checked. DataLoss for anything malformed.
absl::StatusOr<io::RecordingFiles> DecodeRecordingArchive(std::string_view bytes);

// zlib (RFC 1950) at level 6.
absl::StatusOr<std::vector<uint8_t>> Deflate(std::string_view bytes);
// Streaming inflate that stops with DataLoss past `max_bytes` of output, so
// a small hostile blob cannot expand without bound.
absl::StatusOr<std::string> Inflate(const std::vector<uint8_t>& z, size_t max_bytes);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_RECORDING_ARCHIVE_H_
