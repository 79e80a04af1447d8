// What the service does with stored data, as plain library calls (the gRPC
// server only translates protobuf to these): fit a serial's latest run into
// a new calibration version with a verdict, evaluate and export tables from
// a stored calibration, and fleet statistics.
#ifndef FLUXCAL_STORAGE_OPERATIONS_H_
#define FLUXCAL_STORAGE_OPERATIONS_H_

#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "fitting/calibration.h"
#include "storage/store.h"
#include "tables/tables.h"

namespace fluxcal::storage {

struct FitTolerances {
  double max_rms_relative = 0.02;          // fit residual vs the identified points
  double psi_pm_tolerance_relative = 0.10; // vs the nominal magnet flux
};

// Fits the latest run of `serial` and stores calibration version n+1.
absl::StatusOr<CalibrationRow> FitSerial(Store& store, const std::string& serial, const std::string& model,
                                         const FitTolerances& tol);

absl::StatusOr<fit::Calibration> LoadCalibration(Store& store, const std::string& serial, int version);

struct ExportResult {
  tables::Exported exported;
  int version = 0;
  int clamped_cells = 0;
};
absl::StatusOr<ExportResult> ExportTable(Store& store, const std::string& serial, int version,
                                         const tables::TableSpec& spec, const tables::MachineLimits& limits,
                                         const std::string& format);

struct FleetPoint {
  double id_a = 0, iq_a = 0;
  int serials = 0;
  double ldd_mean = 0, ldd_std = 0, lqq_mean = 0, lqq_std = 0, psi_d_mean = 0, psi_d_std = 0;
  double torque_mean = 0, torque_std = 0;
  std::vector<std::string> outliers;
};
absl::StatusOr<std::vector<FleetPoint>> FleetStatistics(Store& store, const std::vector<std::pair<double, double>>& points,
                                                        double outlier_sigma);

}  // namespace fluxcal::storage

#endif  // FLUXCAL_STORAGE_OPERATIONS_H_
