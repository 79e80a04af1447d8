// The diagnosis of a recording set held here (`fluxcal diagnose SET`,
// `--table1`) and the forms its result takes, for the CLI and the service
// (whose DiagnoseStored is in pipeline/pipeline.h). The report type is
// diagnosis/diagnose.h's (diag::DiagnosisReport, the fluxcal.diagnosis.v1
// document's content): it is what these use cases return, so this header
// exposes it.
#ifndef FLUXCAL_PIPELINE_DIAGNOSE_H_
#define FLUXCAL_PIPELINE_DIAGNOSE_H_

#include <array>
#include <set>
#include <string>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "diagnosis/diagnose.h"
#include "io/recording_set.h"

namespace fluxcal::pipeline {

// Paper Table 1 (a CSV of HF and steady-state Lq, diag::ReadTable1) read
// and diagnosed.
absl::StatusOr<diag::Table1Result> DiagnoseTable1File(const std::string& path);

// True when `name` is an effect of the twin's registry (simulation/effects.h).
bool IsKnownEffect(const std::string& name);

// The set's diagnosis (diag::Diagnose), leaving out `excluded_effects`.
absl::StatusOr<diag::DiagnosisReport> DiagnoseSet(const io::RecordingSet& set,
                                                  const std::set<std::string>& excluded_effects = {});

// The figures of a diagnosis, in this order: the residual map before and
// after the findings, the replay spectrum (SVG).
std::array<std::string, 3> DiagnosisFigures(const diag::DiagnosisReport& report);

// The diagnosed model as a calibration (fitting's families, refitted on the
// data freed of the findings), as JSON marked with what was found.
absl::StatusOr<nlohmann::json> DiagnosedCalibrationJson(const diag::DiagnosisReport& report);

// The fluxcal.diagnosis.v1 document and its text form.
nlohmann::json DiagnosisJson(const diag::DiagnosisReport& report);
std::string DiagnosisText(const diag::DiagnosisReport& report);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_DIAGNOSE_H_
