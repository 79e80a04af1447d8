// What an ingest stream carried, in one canonical form that the service,
// `fluxcal eol` and clients/python compute alike (docs/service.md, "Stream
// rules"). The service answers every ingest with the count and the digest
// of what it accepted and stored, so a client compares them with what it
// sent; a client that declares its stream's end (StreamEnd in the last
// message) has the declaration checked against what arrived before
// anything is stored.
#ifndef FLUXCAL_PIPELINE_INGEST_STREAM_H_
#define FLUXCAL_PIPELINE_INGEST_STREAM_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "io/recording_set.h"
#include "pipeline/points.h"
#include "storage/store.h"

namespace fluxcal::pipeline {

// SHA-256 over the bytes "fluxcal.hf-points.v1\n" and then, per point in
// stream order: point_id as a 4-byte big-endian length and its bytes;
// id_a, iq_a, speed_rpm, ld_h, lq_h as IEEE-754 binary64, big-endian; the
// byte 1 and ldq_h (binary64) when ldq_h is present, else the byte 0;
// ld_h_std, lq_h_std, ldq_h_std, temperature_c (binary64); the byte
// `reliable` (0 or 1). Binary doubles: no decimal formatting to agree on,
// and the wire (protobuf) and both store backends keep every bit -- except
// the sign of zero (SQLite stores -0.0 as the integer 0), so a zero is
// hashed as +0.0.
std::string HfPointsSha256(const std::vector<IdentifiedPoint>& points);

// SHA-256 over the bytes "fluxcal.recording-files.v1\n" and then, per file
// in bytewise name order (io::RecordingFiles is that map): the name as a
// 4-byte big-endian length and its bytes, the data as an 8-byte big-endian
// length and its bytes.
std::string RecordingFilesSha256(const io::RecordingFiles& files);
// Data bytes over all files.
int64_t RecordingFilesBytes(const io::RecordingFiles& files);

// A stream's totals: as the client declares them in its last message
// (StreamEnd) or as the server received them.
struct StreamTotals {
  int64_t messages = 0;   // the end message included
  int64_t count = 0;      // points (IngestHfResults) or files (IngestRecording)
  int64_t bytes = 0;      // IngestRecording: data bytes over all files; 0 otherwise
  std::string sha256;     // HfPointsSha256 or RecordingFilesSha256
};
// OK when they agree; else InvalidArgument naming the first field that
// differs (`field` + ".messages", ".count", ".bytes", ".sha256") with the
// declared and the received value, and `what` (e.g. "points").
absl::Status CheckStreamEnd(const StreamTotals& declared, const StreamTotals& received, const std::string& field,
                            const std::string& what);

// A client's check of an ingest reply: what the service says it stored
// (count, bytes, digest; `messages` is not compared) against what the
// client sent. DataLoss naming the first that differs with both values and
// `what` ("points", "files").
absl::Status CheckStored(const StreamTotals& sent, const StreamTotals& stored, const std::string& what);

// The count and HfPointsSha256 of an ingested run, for the reply: for a
// new run, of the points handed to the store in its transaction (`points`);
// for a replay (the idempotency key named a run stored before), of that
// run's points read back from the store -- so a retry whose content differs
// from the first try does not pass the client's check.
struct RunDigest {
  int64_t points = 0;
  std::string points_sha256;
};
absl::StatusOr<RunDigest> DigestOfIngest(storage::Store& store, int64_t run_id, bool replayed,
                                         const std::vector<IdentifiedPoint>& points);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_INGEST_STREAM_H_
