// Chain anchors: the head of the store's hash chains (storage::ChainHead)
// written outside the database, so that a newest calibration version or
// release removed later together with its chain link -- which the chains
// alone cannot show -- is still found (docs/security.md, "Anchors").
//
// An anchor file holds one JSON document per line (format
// "fluxcal.chain-anchor.v1"), appended, never rewritten:
//   {"format": "fluxcal.chain-anchor.v1", "kind": "snapshot" | "event",
//    "created_utc": "...", "backend": "sqlite" | "postgresql",
//    "calibrations": [{"serial": "IPM-1", "version": 3, "row_sha256": "..."}, ...],
//    "release": {"seq": 7, "serial": "IPM-1", "version": 2, "row_sha256": "..."},
//    "digest_sha256": "..."}
// A "snapshot" (`fluxcal admin anchor`) lists every serial's newest chained
// version and carries the digest (storage::ChainHeadDigest); an "event"
// (`fluxcal serve --anchor-file`, after a write) lists the serial written.
// "release" is absent while nothing is released. The file is read as one
// anchor: per serial the highest version any line names, and the highest
// release.
#ifndef FLUXCAL_PIPELINE_ANCHOR_H_
#define FLUXCAL_PIPELINE_ANCHOR_H_

#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "storage/store.h"

namespace fluxcal::pipeline {

inline constexpr char kAnchorFormat[] = "fluxcal.chain-anchor.v1";

// One anchor line (JSON, no newline).
std::string AnchorLine(const storage::ChainHead& head, const std::string& kind, const std::string& backend,
                       const std::string& created_utc);

// Appends `line` and a newline to `path` (created with mode 0644 if
// missing) with one write on an O_APPEND descriptor, then fsync: lines from
// several servers never interleave, and a line is on disk when this
// returns. Unavailable naming the path when it cannot be written.
absl::Status AppendAnchorLine(const std::string& path, const std::string& line);

struct Anchor {
  storage::ChainHead head;   // folded over every line; digest_sha256 empty
  int lines = 0;
  std::string newest_utc;    // created_utc of the last line
};
// Reads an anchor file: NotFound when it does not exist; InvalidArgument
// naming `path:line` and the field for a malformed line or an empty file.
absl::StatusOr<Anchor> ReadAnchorFile(const std::string& path);

// `fluxcal admin anchor`: the store's current head; with a non-empty
// `out_path` also appended there as a snapshot line.
absl::StatusOr<storage::ChainHead> AnchorStore(storage::Store& store, const std::string& out_path);

// After a write the service made (`fluxcal serve --anchor-file`): the
// serial's newest version and the release head, as an event line.
absl::Status AppendAnchorEvent(storage::Store& store, const std::string& path, const std::string& serial);

// `fluxcal admin verify-db [--anchor FILE]`: both chains recomputed
// (storage::VerifyChains) and, with an anchor file, compared with it.
absl::StatusOr<storage::ChainReport> VerifyStore(storage::Store& store, const std::string& anchor_path);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_ANCHOR_H_
