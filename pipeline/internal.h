// The application layer's own parts shared between its files (not a
// public API; nothing outside pipeline/ includes this).
#ifndef FLUXCAL_PIPELINE_INTERNAL_H_
#define FLUXCAL_PIPELINE_INTERNAL_H_

#include <cstddef>
#include <cstdint>
#include <string>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "pipeline/pipeline.h"
#include "storage/store.h"

namespace fluxcal::pipeline::internal {

// The raw recording a run of `serial` was ingested with (NotFound: a run
// of HF results only). ingest.cc.
absl::StatusOr<std::string> RecordingShaOfRun(storage::Store& store, const std::string& serial, int64_t run_id);

// A new calibration version's row for `serial` (`motor` its stored row), fitted from run `run_id`
// over `points` points (`unreliable` of them flagged): its summary fields
// and Verdict, no model yet. fit_serial.cc.
storage::CalibrationRow NewCalibrationRow(const std::string& serial, const storage::MotorRow& motor, int64_t run_id,
                                          const fit::Calibration& cal, size_t points, size_t unreliable,
                                          const FitTolerances& tol);

}  // namespace fluxcal::pipeline::internal

#endif  // FLUXCAL_PIPELINE_INTERNAL_H_
