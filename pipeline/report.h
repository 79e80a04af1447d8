// The report page (report/report.h) assembled from what fluxcal knows about
// a calibration, written once for both producers: `fluxcal report
// cal.json` (a file) and the service's GetReport (a stored version, which
// `fluxcal report SERIAL --server` writes out as served).
#ifndef FLUXCAL_PIPELINE_REPORT_H_
#define FLUXCAL_PIPELINE_REPORT_H_

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "fitting/fit.h"
#include "identification/identify.h"
#include "io/flux_map.h"
#include "io/recording_set.h"
#include "pipeline/pipeline.h"
#include "report/report.h"
#include "storage/store.h"

namespace fluxcal::pipeline {

// What every page takes from the calibration and its JSON alone, whoever
// read it: the verdict (as stored when the JSON carries one, else judged
// from the fit alone), the findings a diagnosed calibration carries (the
// "diagnosis" block of diag::MarkedCalibrationJson) and the version of the
// software writing the page. `cal` must outlive `in`. A caller that knows
// more (a recording set, a diagnosis document) overrides fields afterwards.
void FillReportInputsFromJson(const fit::Calibration& cal, const nlohmann::json& cal_json, report::ReportInputs* in);

// What a recording set adds to a page built here (`fluxcal report cal.json
// --set DIR`): its points identified again, with its hf_results rows and
// its steady-state rows (all drawn over the fitted surfaces, and their
// signed currents say which half of the current plane was measured), the
// manifest's Udc when the caller gave none, and the verdict as the EOL
// flow judges it (Verdict: the manifest's nominal psi_pm, point flags).
// `measured` receives the points; it must outlive `in`. Errors:
// InvalidArgument when the set's serial is not the calibration's (naming
// manifest.json's field 'serial'), identification failures.
absl::Status AddRecordingSetToReport(const io::RecordingSet& set, const std::string& set_dir,
                                     const ident::IdentifyOptions& options, fit::FitData* measured,
                                     report::ReportInputs* in);

// A flux map's nodes over the page's surfaces (`--map`), appended to
// `measured` (which must outlive `in`).
void AddFluxMapToReport(const io::FluxMap& map, const std::string& path, fit::FitData* measured,
                        report::ReportInputs* in);

// The diagnosis of a set, run here (`--set DIR --diagnose`), as the page
// shows it: its fluxcal.diagnosis.v1 document, the residual maps before
// and after the findings and the replay spectrum (diag::ResidualMapSvg,
// SpectrumSvg: the figures of `fluxcal diagnose --plots`). Errors: the
// diagnosis' own (a set without waveforms cannot be diagnosed).
absl::Status AddDiagnosisOfSetToReport(const io::RecordingSet& set, const std::string& set_dir,
                                       report::ReportInputs* in);

// A diagnosis document given as a file (`--diagnosis D.json`): its tables,
// and the replay spectrum drawn from its waveform block. The residual maps
// need the per-point residuals, which the document does not carry: the
// page says so and how to get them.
void AddDiagnosisDocumentToReport(const nlohmann::json& doc, const std::string& path, report::ReportInputs* in);

// What only the store knows about a stored version, merged into its JSON
// under the keys the page reads: version, created_utc, the stored verdict
// (when there is one) and the release state ("released for flashing" /
// "not released"; nullopt: unknown, left out). For the service's page and
// for `fluxcal report SERIAL --server` with local extras, which reads the
// same facts over the API.
void MergeStoredProvenance(int version, const std::string& created_utc, const std::string& verdict,
                           std::optional<bool> released, nlohmann::json* cal_json);

// The page of everything gathered in `in` (report::BuildReport), for the
// page built here (`fluxcal report cal.json`).
absl::StatusOr<report::Report> BuildReportPage(const report::ReportInputs& in);

// Where a page's Udc came from when the caller gave it: the same words for
// the service's page (GetReport's udc_v) and `fluxcal report --udc-v`, so
// that both pages of one version carry the same limits section.
inline constexpr char kUdcFromRequest[] = "udc_v of the request (fluxcal report --udc-v)";

struct StoredReportOptions {
  double speed_rpm = 0;        // voltage-limit curve, mechanical rpm; <= 0: 1.5 x base speed
  double udc_v = 0;            // DC-link voltage; <= 0: the calibration's (none: no voltage limit drawn)
  bool include_fleet = true;   // FleetStatistics at its default points
};

struct StoredReport {
  report::Report page;        // html, figures, voltage-limit speed
  std::string html_sha256;    // io::Sha256Hex(page.html)
  std::string serial;
  int version = 0;            // resolved (0 asked: the latest)
  std::string verdict;        // as stored
  bool fleet_included = false;
};

// The page of calibration `version` (0: latest) of `serial` as stored: its
// JSON with the store's provenance merged (version, created_utc, the stored
// verdict, release state), the findings when it is a diagnosed version,
// the fleet comparison when asked, then report::BuildReport. `cancelled`
// is polled between the steps and per fleet calibration (the page itself
// is built in one go, about a second).
// Errors: NotFound (serial or version), DataLoss (stored JSON unreadable),
// FailedPrecondition (no page can be drawn from the stored calibration),
// Cancelled, or the store's.
absl::StatusOr<StoredReport> BuildStoredReport(storage::Store& store, const std::string& serial, int version,
                                               const StoredReportOptions& options = {},
                                               const CancelledFn& cancelled = {});

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_REPORT_H_
