// The identified HF point: one type (storage::HfPointRow, as stored) and its
// converters to and from every shape, written once: identification
// results, fitting observations and the wire message (v1::HfPoint, used by
// the server and by the EOL client).
#ifndef FLUXCAL_PIPELINE_POINTS_H_
#define FLUXCAL_PIPELINE_POINTS_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "fitting/fit.h"
#include "fluxcal/v1/calibration.pb.h"
#include "identification/identify.h"
#include "io/recording_set.h"
#include "storage/store.h"

namespace fluxcal::pipeline {

using IdentifiedPoint = storage::HfPointRow;

// From identification; false when the point was not identified (NaN values,
// flag identification_failed), which then must not be stored or fitted.
bool FromIdentification(const ident::HfPointResult& r, IdentifiedPoint* out);
// To a fitting observation (Ldd = ld_h, Lqq = lq_h, Ldq = ldq_h).
fit::InductanceObservation ToObservation(const IdentifiedPoint& p);
// The wire message and back (every field; ldq_h absent stays absent).
v1::HfPoint ToProto(const IdentifiedPoint& p);
IdentifiedPoint FromProto(const v1::HfPoint& p);

// Identification of a whole set: the identified points (manifest order,
// failed points left out) and one line per point that was not identified.
struct IdentifiedSet {
  std::vector<ident::HfPointResult> results;   // every point, as identified
  std::vector<IdentifiedPoint> points;
  std::vector<std::string> failures;          // "p003: <reason>"
};
absl::StatusOr<IdentifiedSet> IdentifySet(const io::RecordingSet& set, const ident::IdentifyOptions& options = {});

// Fit input from stored HF points: the motor's nominal data (pole pairs;
// Rs and the magnet flux, as the prior, when > 0: the store keeps 0 for
// "not stated"; no Udc, which a run of HF results does not carry) and one
// inductance observation per point.
fit::FitData FitDataFromPoints(const storage::MotorRow& motor, const std::vector<IdentifiedPoint>& points);

// The identify-then-fit glue (the only place): every data kind a local set
// carries (identified inductances, steady-state rows, hf_results) as fit
// input.
absl::StatusOr<fit::FitData> FitDataFromSet(const io::RecordingSet& set, const ident::IdentifyOptions& options = {});

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_POINTS_H_
