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
//               drive.udc_v); needed by fw and mtpv, refused naming
//               --udc-v / udc_v when neither states it; mtpa needs none;
//   Rs          the request's, else the calibration's; needed by fw
//               (the steady-state voltage), refused naming --rs-ohm /
//               rs_ohm when neither states it.
// A table with more than kMaxClampedShare of its cells clamped is
// refused (FailedPrecondition, saying how many cells and which limit)
// unless allow_clamped.
#ifndef FLUXCAL_TABLES_EXPORT_RULE_H_
#define FLUXCAL_TABLES_EXPORT_RULE_H_

#include <optional>
#include <string>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "tables/tables.h"

namespace fluxcal::tables {

// What the caller of an export states; unset: the calibration's.
struct ExportRequest {
  std::optional<double> i_max_a, udc_v, rs_ohm;
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

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TABLES_EXPORT_RULE_H_
