// MTPA, MTPV and field-weakening lookup tables from a flux-linkage model
// (sim::MagneticModel, e.g. a fitted calibration), and their exporters for
// ECU flashing. Torque and voltage always come from flux linkage:
//   T = 1.5 p (psi_d iq - psi_q id),
//   u = Rs i + w J psi(i)  (steady state, docs/recording-format.md),
// never from the differential inductance used as apparent. See
// docs/tables.md for the solver and the payload/checksum definition.
#ifndef FLUXCAL_TABLES_TABLES_H_
#define FLUXCAL_TABLES_TABLES_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "simulation/magnetic_model.h"

namespace fluxcal::tables {

struct MachineLimits {
  int pole_pairs = 4;
  double rs_ohm = 0.011;
  double i_max_a = 150.0;           // current limit (peak, amplitude-invariant)
  double udc_v = 50.0;
  double modulation_limit = 1.0;    // fraction of the linear SVPWM range
  double temperature_c = 25.0;
  // u_max = m Udc / sqrt(3): the linear range of space-vector PWM.
  double UMaxV() const;
};

struct Axis {
  std::string name;    // e.g. "torque_nm", "speed_rpm", "psi_wb"
  std::vector<double> values;
};

struct Output {
  std::string name;    // e.g. "id_a", "iq_a"
  std::vector<double> values;   // row-major over the axes (first axis slowest)
};

struct Table {
  std::string kind;    // "mtpa", "mtpv", "fw"
  std::string serial;
  int calibration_version = 0;
  std::string model;
  std::string created_utc;
  std::vector<Axis> axes;
  std::vector<Output> outputs;
  std::vector<uint8_t> clamped;   // per cell: 1 where the request exceeded the limits
  // Over the canonical payload (PayloadBytes): CRC-32 (zlib) and SHA-256.
  uint32_t crc32 = 0;
  std::string sha256;
};

struct TableSpec {
  std::string kind = "mtpa";        // mtpa | mtpv | fw
  int points = 64;                  // rows of a curve / torque axis of the map
  int speed_points = 32;            // fw: speed axis
  double speed_max_rpm = 6000.0;    // fw: speed axis range [0, max]
  bool include_generating = true;   // negative torque rows (mtpa, fw)
  std::string serial;
  int calibration_version = 0;
  std::string model;
};

double TorqueNm(const sim::MagneticModel& m, int pole_pairs, double id_a, double iq_a,
                double temperature_c = 25.0);
// Steady-state voltage magnitude at electrical speed w_e.
double VoltageV(const sim::MagneticModel& m, const MachineLimits& lim, double id_a, double iq_a,
                double we_rad_s);

// Least-current operating point for a torque request, optionally under a
// voltage limit at electrical speed we_rad_s (<= 0: no voltage limit).
struct OperatingPoint {
  double id_a = 0, iq_a = 0, torque_nm = 0;
  bool clamped = false;
};
OperatingPoint SolveLeastCurrent(const sim::MagneticModel& m, const MachineLimits& lim,
                                 double torque_nm, double we_rad_s);
// Largest torque magnitude at the current limit (and voltage limit when
// we_rad_s > 0), motoring (sign > 0) or generating (sign < 0).
double MaxTorqueNm(const sim::MagneticModel& m, const MachineLimits& lim, double we_rad_s,
                   double sign = 1.0);

absl::StatusOr<Table> BuildTable(const sim::MagneticModel& m, const MachineLimits& lim,
                                 const TableSpec& spec);

// Canonical payload: for each axis then each output, its values as IEEE-754
// float64 little endian, in declaration order (docs/tables.md).
std::string PayloadBytes(const Table& t);
void Seal(Table* t);   // fills crc32 and sha256

enum class Format { kCsv, kJson, kCHeader, kCdfx, kDcm };
absl::StatusOr<Format> ParseFormat(const std::string& name);
struct Exported {
  std::string bytes;
  uint32_t crc32 = 0;
  std::string sha256;
};
absl::StatusOr<Exported> Export(const Table& t, Format f);

// SVG plots: MTPA/MTPV over torque contours in the (id, iq) plane; the
// field-weakening table as a heat map.
std::string PlotCurvesSvg(const sim::MagneticModel& m, const MachineLimits& lim, const Table& mtpa,
                          const Table* mtpv);
std::string PlotMapSvg(const Table& fw, const std::string& output_name);

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TABLES_TABLES_H_
