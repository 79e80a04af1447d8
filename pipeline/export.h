// The export use case, written once for both of its callers: `fluxcal
// export cal.json` (a calibration held here, ExportCalibration) and the
// service's ExportTable RPC (a stored version, ExportTable, which reads the
// version and then takes the same path). Before, the CLI kept its own copy
// of the steps, and the copies had drifted (the service fell back to
// 150 A without a measured current limit, the CLI refused); the limits
// themselves are decided by the export rule (tables/export_rule.h).
#ifndef FLUXCAL_PIPELINE_EXPORT_H_
#define FLUXCAL_PIPELINE_EXPORT_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "storage/store.h"
#include "tables/export_rule.h"
#include "tables/tables.h"

namespace fluxcal::pipeline {

struct ExportResult {
  tables::Exported exported;
  tables::Table table;           // as written (verdict, release state, flags)
  tables::ClampSummary clamped;  // cells, clamped cells, share and why
  int version = 0;
  int cells = 0;
  int clamped_cells = 0;
  int extrapolated_cells = 0;
  std::string verdict;     // the stored verdict of the exported version (ExportTable; empty for a file)
  bool released = false;   // the version is released for flashing (ExportTable)
  tables::ExportLimits limits;   // what the table was computed for, and from where
};

// The `spec` table of `cal` under the export rule (limits from `request`,
// else the calibration; refused when mostly clamped), written as `format`
// (csv|json|h|cdfx|dcm|a2l). spec.serial, calibration_version and model are
// taken from `cal` when empty / 0; spec.verdict and release_state are
// written into the file as given (a file alone: tables::kVerdictUnknown and
// kReleaseUnknown, the defaults). Errors: InvalidArgument naming the flag
// or field to give (request.names_flags), FailedPrecondition for a table
// refused for what it would contain, the serialiser's.
absl::StatusOr<ExportResult> ExportCalibration(const fit::Calibration& cal, const tables::TableSpec& spec,
                                               const tables::ExportRequest& request, const std::string& format,
                                               const tables::ExportOptions& options = {});

// ExportCalibration of the stored `version` of `serial` (0: the latest).
// The stored verdict and release state of the version are written into the
// exported file (spec.verdict and spec.release_state are overwritten from
// the store), and returned in `verdict` / `released`.
absl::StatusOr<ExportResult> ExportTable(storage::Store& store, const std::string& serial, int version,
                                         const tables::TableSpec& spec, const tables::ExportRequest& request,
                                         const std::string& format, const tables::ExportOptions& options = {});

// What a table spec asks for, checked before anything is computed
// (tables::CheckExportSpec: --generating / generating only with the
// envelope); ExportCalibration and ExportTable check it too.
absl::Status CheckExportSpec(const tables::TableSpec& spec, const tables::ExportRequest& request);

// The names an export request takes, checked as ExportCalibration checks
// them (tables/tables.h keeps the one list of each): InvalidArgument for a
// name not listed, saying which are.
absl::Status CheckExportFormat(const std::string& name);
absl::StatusOr<tables::CType> ParseExportCType(const std::string& name);
const char* ExportCTypeName(tables::CType ct);   // "double", "float", "int16", "int32"

// The figure of an exported table (`fluxcal export --svg`): the envelope
// as torque and power over speed; the fw map as a
// heat map of id_a; the MTPV table with MTPA beside it for reference; the
// MTPA table with MTPV beside it. The reference table is computed for the
// same limits as `exported` and left out when it cannot be (e.g. no MTPV
// point inside the current limit). `spec` is the one given to the export.
std::string ExportFigureSvg(const fit::Calibration& cal, const tables::TableSpec& spec, const ExportResult& exported);

// A Udc axis (`fluxcal export --udc-axis-v 250,300,350`, docs/tables.md
// "Tables over Udc"): one export per DC-link voltage, each the table of
// ExportCalibration at that voltage (the same values, bit for bit) with its
// labels tagged by the voltage (FLUXCAL_FW_UDC300V_ID_A) and written to its
// own file (UdcAxisPath). request.udc_v must be unset. Errors as
// ExportCalibration's, the first refusal naming its Udc.
struct UdcAxisExport {
  double udc_v = 0;
  ExportResult result;
};
absl::StatusOr<std::vector<UdcAxisExport>> ExportCalibrationOverUdc(const fit::Calibration& cal,
                                                                    const tables::TableSpec& spec,
                                                                    const tables::ExportRequest& request,
                                                                    const std::vector<double>& udc_axis_v,
                                                                    const std::string& format,
                                                                    const tables::ExportOptions& options = {});
// ExportCalibrationOverUdc of the stored `version` of `serial` (0: the
// latest), as ExportTable: the stored verdict and release state written
// into every file and returned once (the service's ExportTable with
// udc_axis_v). Nothing is written to disk.
struct StoredUdcAxisExport {
  int version = 0;
  std::string verdict;
  bool released = false;
  std::vector<UdcAxisExport> tables;
};
absl::StatusOr<StoredUdcAxisExport> ExportTableOverUdc(storage::Store& store, const std::string& serial, int version,
                                                       const tables::TableSpec& spec,
                                                       const tables::ExportRequest& request,
                                                       const std::vector<double>& udc_axis_v,
                                                       const std::string& format,
                                                       const tables::ExportOptions& options = {});
// A file name for a table of `serial` (ExportedUdcTable.file_name):
// SERIAL_KIND[_generating].FORMAT, and with a Udc (> 0) UdcAxisPath of it
// ("IPM-1_fw_udc300v.h"), the names `fluxcal export --udc-axis-v` gives.
std::string ExportFileName(const std::string& serial, const tables::TableSpec& spec, const std::string& format,
                           double udc_v = 0);

// The most voltages of a Udc axis (the CLI's and the service's bound).
inline constexpr int kMaxUdcAxisPoints = tables::kMaxUdcAxisPoints;

// The file of one Udc of an axis: `path` with `_<UdcTag>` before its
// extension ("fw.h" -> "fw_udc300v.h", "out/fw" -> "out/fw_udc300v").
std::string UdcAxisPath(const std::string& path, double udc_v);
// The Udc axis as `--udc-axis-v` gives it (tables::ParseUdcAxis).
absl::StatusOr<std::vector<double>> ParseUdcAxis(const std::string& text);

// The envelope figure of envelope tables, one curve per table (one per Udc
// of an axis): tables::PlotEnvelopeSvg.
std::string EnvelopeFigureSvg(const std::vector<const ExportResult*>& envelopes);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_EXPORT_H_
