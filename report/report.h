// One calibration as one self-contained static HTML page (inline SVG and
// CSS; no script, no network): identity and provenance, verdict and fit
// quality, the differential inductances and flux linkages, MTPA / MTPV on
// the current plane with torque contours and the current and voltage
// limits, the field-weakening maps, the tables' limits and checksums, and
// the diagnosis findings when a diagnosis report is given. Every number on
// the page is computed from the inputs (docs/report.md).
#ifndef FLUXCAL_REPORT_REPORT_H_
#define FLUXCAL_REPORT_REPORT_H_

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "fitting/fit.h"

namespace fluxcal::report {

// Where the fleet stands at one operating point (the service's
// FleetStatistics over the latest calibration of every serial).
struct FleetPoint {
  double id_a = 0, iq_a = 0;
  int serials = 0;
  double ldd_h_mean = 0, ldd_h_std = 0, lqq_h_mean = 0, lqq_h_std = 0;
  double psi_d_wb_mean = 0, psi_d_wb_std = 0, torque_nm_mean = 0, torque_nm_std = 0;
  std::vector<std::string> outliers;   // serials the service flags at this point
};

struct ReportInputs {
  // The calibration and the JSON it was read from (provenance fields the
  // calibration type does not keep: created_utc, software_version,
  // released, verdict, when a producer wrote them).
  const fit::Calibration* calibration = nullptr;
  nlohmann::json calibration_json;
  std::string calibration_path;
  // Where the calibration file's modification time is the only time known.
  std::string calibration_file_mtime_utc;
  // From a recording set (--set): the identified points drawn against the
  // fitted surfaces, and the manifest's DC-link voltage.
  const fit::FitData* identified = nullptr;
  std::string set_path;
  std::optional<double> udc_v;
  std::string udc_source;   // where udc_v came from, said on the page
  // "pass" / "fail: ..." and what it was judged against.
  std::string verdict, verdict_basis;
  // A fluxcal.diagnosis.v1 document (docs/diagnosis-report.md).
  std::optional<nlohmann::json> diagnosis;
  std::string diagnosis_path;
  // Speed for the voltage-limit curve; <= 0: 1.5 x the base speed (where
  // the MTPA point at the current limit reaches the voltage limit).
  double ellipse_speed_rpm = 0;
  std::string software_version;   // of the program writing the report
  // With --server: the fleet this motor is compared with (empty: none).
  std::vector<FleetPoint> fleet;
  std::string fleet_source;
};

struct Report {
  std::string html;
  int figures = 0;
  double ellipse_speed_rpm = 0;
};

// Errors: INVALID_ARGUMENT naming the field when the calibration is missing
// or a table cannot be built from it, or the diagnosis document is not
// fluxcal.diagnosis.v1 (field 'format').
absl::StatusOr<Report> BuildReport(const ReportInputs& in);

}  // namespace fluxcal::report

#endif  // FLUXCAL_REPORT_REPORT_H_
