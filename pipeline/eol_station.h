// The EOL station's use case as a client of the service (`fluxcal eol`):
// identify every point of a recording set here, stream the results for its
// serial, (optionally) upload the raw set, ask for a fit and its verdict,
// and on a pass fetch the ECU tables. Each stream declares its end (count
// and SHA-256 of what it carries), and the reply's count and digest of
// what the service stored must equal what was sent, or the flow stops
// before anything is fitted. The CLI only parses flags, makes the stub,
// writes the tables and prints (before, this lived in cli/cmd_eol.cc).
#ifndef FLUXCAL_PIPELINE_EOL_STATION_H_
#define FLUXCAL_PIPELINE_EOL_STATION_H_

#include <functional>
#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "fluxcal/v1/calibration.grpc.pb.h"
#include "io/recording_set.h"

namespace fluxcal::pipeline {

struct EolStationOptions {
  std::string station_id = "eol";   // recorded with the run
  std::string model = "auto";       // the Fit RPC's model (fit::ParseModelName)
  // Non-empty: the set's directory; its manifest and every file the
  // manifest names are uploaded with IngestRecording (replayable and
  // diagnosable on the service) before the fit.
  std::string upload_recording_dir;
  // On a pass: fetch the MTPA (CDFX) and field-weakening (DCM) tables, each
  // handed to on_table as it arrives (a non-OK status stops the flow).
  bool fetch_tables = false;
  std::function<absl::Status(const std::string& table, const std::string& format,
                             const v1::ExportTableResponse& reply)> on_table;
  // Progress lines for the operator ("eol SERIAL: ..."), without newline.
  std::function<void(const std::string& line)> log;
};

struct EolStationResult {
  std::string serial;
  v1::IngestHfResultsResponse ingest;
  std::optional<v1::IngestRecordingResponse> recording;   // with upload_recording_dir
  v1::FitResponse fit;   // fit.pass(): the verdict
};

// The flow above for `set` (read from options.upload_recording_dir when
// uploading). An RPC that fails (after 3 tries for the two ingests on
// UNAVAILABLE / DEADLINE_EXCEEDED, repeated with the same idempotency key
// so that a retry stores nothing twice) is returned as Unknown with its
// status in *rpc_error, for the caller to report with its setup hints;
// every other error (identification, a stored count or digest not what
// was sent, a file of the set unreadable, on_table's) names the serial,
// run or file, and leaves *rpc_error OK.
absl::StatusOr<EolStationResult> RunEolStation(v1::CalibrationService::StubInterface& stub,
                                               const io::RecordingSet& set, const EolStationOptions& options,
                                               grpc::Status* rpc_error);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_EOL_STATION_H_
