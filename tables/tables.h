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

namespace fluxcal::plot {
class Figure;
}

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

// Release state of the exported calibration version, as written into every
// export: the release store knows it for exports through the service; a
// local export from a calibration file cannot know it.
inline constexpr char kReleased[] = "released";
inline constexpr char kNotReleased[] = "not released";
inline constexpr char kReleaseUnknown[] = "unknown (local export, release store not consulted)";
inline constexpr char kVerdictUnknown[] = "unknown";

struct Table {
  std::string kind;    // "mtpa", "mtpv", "fw"
  // Provenance: written into every export format (docs/tables.md).
  std::string serial;
  int calibration_version = 0;
  std::string model;
  std::string created_utc;
  std::string fluxcal_version;                    // FluxcalVersion() of the build that computed it
  std::string verdict = kVerdictUnknown;          // the calibration's verdict ("pass", ...)
  std::string release_state = kReleaseUnknown;    // kReleased, kNotReleased or kReleaseUnknown
  // What the table was computed for: the limits the solver used, the machine
  // constants, and the measured region of the calibration.
  MachineLimits limits;
  double psi_pm_wb = 0.0;               // psi_d at id = iq = 0 and limits.temperature_c
  double speed_max_rpm = 0.0;           // fw: top of the speed axis [0, max]; 0 for mtpa/mtpv
  double measured_current_limit_a = 0;  // 0: not known (no measured region was given)
  bool allow_extrapolation = false;
  std::vector<Axis> axes;
  std::vector<Output> outputs;
  std::vector<uint8_t> clamped;        // per cell: 1 where the request exceeded the limits
  // Per cell: 1 where |i| lies beyond the measured current limit, or (the
  // model a fit::Calibration) the operating point lies outside its measured
  // region and not on the mirror image of it (fit::Region::kExtrapolated).
  std::vector<uint8_t> extrapolated;
  // Per cell (the model a fit::Calibration): 1 where the operating point lies
  // on the iq half the data did not measure and the model states the
  // measured half mirrored (fit::Region::kBySymmetry): e.g. the generating
  // rows of a calibration from a motoring-only bench.
  std::vector<uint8_t> by_symmetry;
  // Per cell: 1 where the model's differential inductance at the operating
  // point is not positive definite (fit::NotPositiveDefiniteReason): the
  // flux map is not monotone there, the current it yields is not a valid
  // operating point of the model.
  std::vector<uint8_t> not_positive_definite;
  // Over the canonical payload (PayloadBytes), NOT over a file: CRC-32 (zlib)
  // and SHA-256 of the values. Exports name them payload_crc32 / payload_sha256.
  uint32_t crc32 = 0;
  std::string sha256;
};

// Version of fluxcal (CMake project version) written into exports.
const char* FluxcalVersion();

// A scalar written beside the table in every format (DCM FESTWERT, CDFX
// VALUE, C #define, CSV comment, JSON field): name with unit suffix, value,
// unit as displayed, and what it means.
struct Scalar {
  std::string name;
  double value = 0;
  std::string unit;
  std::string description;
  bool integer = false;
};
std::vector<Scalar> Scalars(const Table& t);
// Text metadata (serial, model, created_utc, fluxcal_version, verdict,
// release_state): written as text where the format has text, else comments.
std::vector<std::pair<std::string, std::string>> TextFields(const Table& t);
// Per-cell flag arrays exported beside the outputs, in this order:
// "clamped", "extrapolated", "by_symmetry", "not_positive_definite", each
// 0/1 with the outputs' shape.
std::vector<std::pair<std::string, const std::vector<uint8_t>*>> Flags(const Table& t);

struct TableSpec {
  std::string kind = "mtpa";        // mtpa | mtpv | fw
  int points = 64;                  // rows of a curve / torque axis of the map
  int speed_points = 32;            // fw: speed axis
  double speed_max_rpm = 6000.0;    // fw: speed axis range [0, max]
  bool include_generating = true;   // negative torque rows (mtpa, fw)
  std::string serial;
  int calibration_version = 0;
  std::string model;
  std::string verdict = kVerdictUnknown;
  std::string release_state = kReleaseUnknown;
  // The calibration's measured current limit (fit::Calibration::
  // MeasuredCurrentLimitA); 0: not known, then no cell is marked extrapolated
  // and no extrapolation check is made.
  double measured_current_limit_a = 0;
  // false (default): a current limit above the measured one is refused
  // (InvalidArgument), and the MTPV flux axis is restricted to the fluxes
  // whose MTPV point lies inside the current limit (FailedPrecondition when
  // there is none). true: computed anyway, cells flagged `extrapolated`.
  bool allow_extrapolation = false;
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

// The current plane behind an MTPA / MTPV figure (the export's and the
// report's: one drawing of it): torque contours at round values up to the
// torque at the current limit, the current-limit circle, and for
// we_rad_s > 0 the voltage limit |u| = u_max at that speed, labelled
// `voltage_label`. The fields are sampled over [id_lo_a, 0.6 i_max] x
// [-0.2 i_max, iq_hi_a], beyond the view (equal scaling widens one axis;
// the figure clips at its frame). Returns the circle's points (for a
// second circle drawn to scale).
struct PlaneCircle {
  std::vector<double> id_a, iq_a;
};
PlaneCircle DrawCurrentPlane(plot::Figure* f, const sim::MagneticModel& m, const MachineLimits& lim, double id_lo_a,
                             double iq_hi_a, double we_rad_s, const std::string& voltage_label);

// When `m` is a fit::Calibration, each cell's operating point is placed in
// its measured region (Calibration::RegionOf): `by_symmetry` and
// `extrapolated` flag what does not rest on measured data. Every cell's
// `not_positive_definite` comes from m.Inductance at its operating point.
// Errors: InvalidArgument (points, limits, kind; a current limit above the
// measured one without allow_extrapolation), FailedPrecondition (mtpv: no
// MTPV point inside the current limit and allow_extrapolation not set).
absl::StatusOr<Table> BuildTable(const sim::MagneticModel& m, const MachineLimits& lim,
                                 const TableSpec& spec);

// Canonical payload: for each axis then each output, its values as IEEE-754
// float64 little endian, in declaration order (docs/tables.md).
std::string PayloadBytes(const Table& t);
void Seal(Table* t);   // fills crc32 and sha256

enum class Format { kCsv, kJson, kCHeader, kCdfx, kDcm };
absl::StatusOr<Format> ParseFormat(const std::string& name);
enum class CType { kDouble, kFloat };
// "double" | "float"; InvalidArgument naming --ctype otherwise.
absl::StatusOr<CType> ParseCType(const std::string& name);
struct ExportOptions {
  CType ctype = CType::kDouble;   // C header element type of the value arrays and scalars
};
struct Exported {
  std::string bytes;
  uint32_t payload_crc32 = 0;    // over the values (PayloadBytes), as written inside the file
  std::string payload_sha256;    // over the values (PayloadBytes), as written inside the file
  std::string file_sha256;       // over `bytes`: equals `sha256sum FILE` of the written file
};
// Errors: InvalidArgument (empty table, a non-finite value: named by field).
absl::StatusOr<Exported> Export(const Table& t, Format f, const ExportOptions& opt = {});

// SVG plots (drawn with plot/), the motoring half of the (id, iq) plane on
// equal axes: round-valued torque contours, the current limit circle (and
// the measured one where it differs), the voltage limit at a speed its
// legend states, and the tables' motoring rows; rows flagged clamped or
// extrapolated get their own markers.
// The MTPA table's figure: MTPA bold with a dot per row, the voltage limit
// at 1.5 x base speed; the MTPV table (if given) thin, for reference.
std::string PlotCurvesSvg(const sim::MagneticModel& m, const MachineLimits& lim, const Table& mtpa,
                          const Table* mtpv);
// The MTPV table's figure: MTPV bold with a dot per row, the voltage limit
// at the speed where MTPV operation begins (through its row of largest
// current inside the current limit); the MTPA table (if given) thin.
std::string PlotMtpvSvg(const sim::MagneticModel& m, const MachineLimits& lim, const Table& mtpv,
                        const Table* mtpa);
// The field-weakening table's `output_name` as a heat map over speed and
// torque request, a colour bar with round ticks along its length, a cross
// on each clamped cell and a square on each extrapolated one.
std::string PlotMapSvg(const Table& fw, const std::string& output_name);

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TABLES_TABLES_H_
