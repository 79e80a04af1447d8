// The service's own helpers shared by its RPC files (not a public API;
// nothing outside server/ includes this): cancellation and its status, the
// stored row as a message, the station a run is recorded under, and the
// streams' error statuses.
#ifndef FLUXCAL_SERVER_INTERNAL_H_
#define FLUXCAL_SERVER_INTERNAL_H_

#include <cstdint>
#include <string>

#include <grpcpp/grpcpp.h>

#include "absl/status/status.h"
#include "absl/strings/str_cat.h"
#include "fluxcal/v1/calibration.grpc.pb.h"
#include "pipeline/pipeline.h"
#include "server/auth.h"
#include "server/service.h"

namespace fluxcal::server::internal {

// The client's deadline and cancellation as a plain callback for the
// pipeline's long loops (the libraries know nothing of gRPC).
pipeline::CancelledFn CancelledBy(grpc::ServerContext* ctx);

// Work stopped by CancelledBy: DEADLINE_EXCEEDED when the client's deadline
// passed, CANCELLED when the client went away; other errors as they are.
grpc::Status StoppedOr(grpc::ServerContext* ctx, const absl::Status& s);

void ToProto(const storage::CalibrationRow& c, v1::CalibrationRecord* r);

// The station a run is recorded under: an authenticated station is itself,
// whatever the message claims (a different claim is refused); others
// (admin, open mode) may name one.
absl::Status StationOf(const Identity& who, const std::string& claimed, std::string* station);

// A stream problem at message `m` (0-based): the status with "message m: "
// in front and "; nothing stored" after, its code kept.
grpc::Status AtMessage(int64_t m, const absl::Status& s);

// Read() returned false before the stream's end message: either the client
// closed its side, or the message at `next` failed to parse (gRPC ends the
// reads at a message it cannot parse, whatever follows it). One more Read
// tells the two apart when a message follows the broken one; a stream that
// declared its end (end_follows) is refused either way.
template <class Message>
grpc::Status EndedWithoutEnd(grpc::ServerReader<Message>* reader, Message* scratch, int64_t next, bool end_follows,
                             const std::string& chunks = "") {
  auto at = [&](const std::string& why) {
    if (chunks.empty()) return AtMessage(next, absl::InvalidArgumentError(why));
    return ToGrpcStatus(absl::InvalidArgumentError(absl::StrCat(chunks, "[", next, "]: ", why, "; nothing stored")));
  };
  if (reader->Read(scratch)) {
    return at(absl::StrCat("failed to parse as ", Message::descriptor()->full_name(),
                           " (corrupt, or another message); the stream went on after it"));
  }
  if (end_follows) {
    return at("end: the stream ended without its end message (declared by end_follows): a message failed to "
              "parse or the stream was cut");
  }
  return grpc::Status::OK;
}

}  // namespace fluxcal::server::internal

#endif  // FLUXCAL_SERVER_INTERNAL_H_
