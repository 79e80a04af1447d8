// The export rule, written once for `fluxcal export cal.json` (a file),
// the service's ExportTable (pipeline::ExportTable, a stored version) and
// the report page's tables: which limits a table is
// computed for, where each comes from, and when a table is refused for
// being mostly clamped (docs/tables.md, "Limits and the export rule").
//
//   pole pairs  the calibration's (always known);
//   i_max       the request's, else the calibration's measured current
//               limit; neither: refused naming --i-max-a / i_max_a;
//   Udc         the request's, else the calibration's (its set's
//               drive.udc_v); needed by fw, mtpv and envelope, refused naming
//               --udc-v / udc_v when neither states it; mtpa needs none;
//   Rs          the request's, else the calibration's; needed by fw
//               and envelope (the steady-state voltage), refused naming
//               --rs-ohm / rs_ohm when neither states it;
//   magnet T    unset: the flux map as it is; requested: psi_pm scaled
//               by the calibration's own coefficient (MagnetTemperatureOf),
//               refused while calibrations state none.
// A table with more than kMaxClampedShare of its cells clamped is
// refused (FailedPrecondition, saying how many cells and which limit)
// unless allow_clamped.
#ifndef FLUXCAL_TABLES_EXPORT_RULE_H_
#define FLUXCAL_TABLES_EXPORT_RULE_H_

#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "tables/tables.h"

namespace fluxcal::tables {

// What the caller of an export states; unset: the calibration's.
struct ExportRequest {
  std::optional<double> i_max_a, udc_v, rs_ohm;
  // The magnet temperature to compute the table at (--magnet-temp-c,
  // degC); unset: the calibration's flux map as it is. Needs the
  // calibration's own temperature coefficient (MagnetTemperatureOf).
  std::optional<double> magnet_temp_c;
  bool allow_clamped = false;
  // How errors name the inputs: command-line flags (--udc-v) or the RPC's
  // request fields (udc_v).
  bool names_flags = true;
};

struct ExportLimits {
  MachineLimits limits;
  // Where each came from, in words ("--udc-v", "the calibration (its set's
  // drive.udc_v)", "the calibration's measured current limit"); empty when
  // not used (Udc and Rs of an MTPA table the calibration does not state).
  std::string i_max_source, udc_source, rs_source;
  // A request value that replaced a different one of the calibration
  // (e.g. "--udc-v 48 V replaces the calibration's 50 V"); empty if none.
  std::string overridden;
};

// The limits of a `kind` table of `cal` under the rule above.
// InvalidArgument naming the flag / field when one that is needed is
// unknown or out of range.
absl::StatusOr<ExportLimits> ResolveExportLimits(const fit::Calibration& cal, const std::string& kind,
                                                 const ExportRequest& request);

// What a table spec asks for, checked before anything is computed (and
// again by BuildExportTable): spec.envelope_generating only with kind
// envelope (InvalidArgument naming --generating / generating otherwise).
absl::Status CheckExportSpec(const TableSpec& spec, const ExportRequest& request);

struct BuiltExport {
  Table table;
  ExportLimits limits;
  ClampSummary clamped;
};
// The table `spec` asks for, computed under ResolveExportLimits, with the
// calibration's measured current limit written into it; refused when
// mostly clamped (above). spec.serial, calibration_version and model are
// taken from `cal` when empty / 0.
absl::StatusOr<BuiltExport> BuildExportTable(const fit::Calibration& cal, TableSpec spec,
                                             const ExportRequest& request);

// The magnet temperature `at_c` under the calibration's own coefficient
// of psi_pm and the temperature its flux map holds (tables.h,
// MagnetTemperature; fit::Calibration::psi_pm_temp_coeff_per_k and
// magnet_reference_c, with the reference's spread). Either unknown:
// InvalidArgument naming --magnet-temp-c / magnet_temp_c and exactly what
// is missing (no textbook coefficient or temperature is put in its place);
// also for `at_c` outside -60 .. 250 degC.
absl::StatusOr<MagnetTemperature> MagnetTemperatureOf(const fit::Calibration& cal, double at_c,
                                                      const ExportRequest& request);

// One line on a table at a magnet temperature (what `fluxcal export`
// prints): the scale and where alpha and T_ref come from, and a warning
// when the flux map's temperatures spread more than
// fit::kMagnetReferenceSpreadWarnK.
std::string MagnetTemperatureNote(const MagnetTemperature& mt);

// A Udc axis (docs/tables.md, "Tables over Udc"): the DC-link voltages
// of `--udc-axis-v`, written as a list "250,300,350,400" or a range
// "LO:HI:N" (N evenly spaced voltages from LO to HI, N >= 2). At most
// kMaxUdcAxisPoints, each in (0, 5000] V, strictly increasing, and no two
// with the same label tag (UdcTag). InvalidArgument naming `flag` otherwise.
inline constexpr int kMaxUdcAxisPoints = 32;
absl::StatusOr<std::vector<double>> ParseUdcAxis(const std::string& text, const std::string& flag = "--udc-axis-v");

// One BuildExportTable per voltage of `udc_axis_v`, each with request.udc_v
// the voltage and its labels tagged with it (UdcTag: FLUXCAL_FW_UDC300V_ID_A),
// so that the tables can sit side by side in one ECU build. Each table's
// values are those of the single export at that Udc (the same
// computation); request.udc_v must be unset (InvalidArgument: the axis
// replaces it). The first refusal (e.g. mostly clamped at the lowest Udc)
// is returned, naming its Udc.
absl::StatusOr<std::vector<BuiltExport>> BuildExportTablesOverUdc(const fit::Calibration& cal, const TableSpec& spec,
                                                                  const ExportRequest& request,
                                                                  const std::vector<double>& udc_axis_v);

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TABLES_EXPORT_RULE_H_
