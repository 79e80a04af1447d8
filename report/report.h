// One calibration as one self-contained static HTML page (inline SVG and
// CSS; no script, no network): identity and provenance, verdict and fit
// quality (with where the inductance is not positive definite), the
// differential inductances and flux linkages with the measured points over
// them, MTPA / MTPV on the current plane in both torque directions with
// torque contours and the current and voltage limits, the torque-speed
// envelope, the field-weakening maps, the tables' limits and checksums,
// and the diagnosis (findings, residual maps and spectrum) when one is
// given. What lies outside the measured region is drawn dashed or dotted
// and labelled (by symmetry / extrapolated). Every number on the page is
// computed from the inputs and rounded to its meaning (report/format.h);
// docs/report.md.
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

// A figure made elsewhere (an SVG element) and its caption, as the page
// embeds it: the diagnosis' residual maps and spectrum.
struct EmbeddedFigure {
  std::string svg;
  std::string caption;   // plain text (escaped on the page)
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
  // What was measured, drawn over the fitted surfaces and curves: a
  // recording set's identified inductances and steady-state rows (--set),
  // a flux map's nodes (--map). Their signed currents also say which half
  // of the current plane (iq > 0, iq < 0) was measured.
  const fit::FitData* identified = nullptr;
  std::string set_path;
  std::string map_path;
  std::optional<double> udc_v;
  std::string udc_source;   // where udc_v came from, said on the page
  // "pass" / "fail: ..." and what it was judged against.
  std::string verdict, verdict_basis;
  // A fluxcal.diagnosis.v1 document (docs/diagnosis-report.md).
  std::optional<nlohmann::json> diagnosis;
  std::string diagnosis_path;
  // The diagnosis' figures (residual maps, replay spectrum), with a line
  // that says where they come from or why some are missing.
  std::vector<EmbeddedFigure> diagnosis_figures;
  std::string diagnosis_figures_note;
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
