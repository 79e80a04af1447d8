// The binary form of a fitted calibration (fluxcal.v1.CalibrationModel,
// proto/fluxcal/v1/calibration_model.proto): what the store keeps per
// calibration version since schema v8. JSON (fluxcal.calibration.v1) stays
// the export and the view; these functions convert between the two.
//
// Exact both ways: fit::Calibration holds its covariance at float precision
// (fitting/calibration.h), which the message stores as float32 (the packed
// upper triangle), every other number as a double. So
//   Calibration -> binary -> Calibration -> binary   is bit-identical, and
//   JSON (as ToJson wrote it) -> binary -> JSON      is the same text.
// Top-level JSON members a Calibration does not hold (the "diagnosis" block
// of diag::MarkedCalibrationJson) travel as compact JSON in extra_json.
//
// Errors: InvalidArgument (JSON that is not a calibration, a message that
// does not parse or does not fit its family: DataLoss for the latter when
// it came from the store, StoredCalibration*).
#ifndef FLUXCAL_PIPELINE_CALIBRATION_CODEC_H_
#define FLUXCAL_PIPELINE_CALIBRATION_CODEC_H_

#include <string>
#include <string_view>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "storage/store.h"

namespace fluxcal::pipeline {

// The calibration as serialised bytes; `extra` (an object, or null) is kept
// in extra_json.
std::string EncodeCalibration(const fit::Calibration& cal, const nlohmann::json& extra = nullptr);
// Back from bytes; `extra` (optional) receives extra_json (null when none).
absl::StatusOr<fit::Calibration> DecodeCalibration(std::string_view bytes, nlohmann::json* extra = nullptr);

// JSON text (fluxcal.calibration.v1) -> bytes: what AddCalibration stores
// and the v8 migration converts with (storage::JsonToModelFn).
absl::StatusOr<std::string> CalibrationJsonToModel(const std::string& calibration_json);
// Bytes -> the JSON document (ToJson plus the extra members).
absl::StatusOr<nlohmann::json> CalibrationModelToJson(std::string_view bytes);

// A stored version's calibration and its JSON view, whichever form the row
// holds (model_pb, or calibration_json for a version the v8 migration left
// as JSON). DataLoss when the stored content does not read.
absl::StatusOr<nlohmann::json> StoredCalibrationJson(const storage::CalibrationRow& row);
absl::StatusOr<std::string> StoredCalibrationJsonText(const storage::CalibrationRow& row);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_CALIBRATION_CODEC_H_
