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
#include <optional>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "simulation/magnetic_model.h"

namespace fluxcal::plot {
class Figure;
}

namespace fluxcal::tables {

// The machine and drive a table is computed for. Nothing here has a
// default of some machine: pole pairs and the current limit must be given
// (BuildTable refuses 0), Rs and Udc where a voltage is computed (the
// field-weakening map; tables/export_rule.h says where each comes from).
struct MachineLimits {
  int pole_pairs = 0;               // required, 1..100
  std::optional<double> rs_ohm;     // nominal Rs; needed for voltages
  double i_max_a = 0;               // current limit (peak, amplitude-invariant); required > 0
  std::optional<double> udc_v;      // DC-link voltage; needed for the voltage limit
  double modulation_limit = 1.0;    // fraction of the linear SVPWM range
  double temperature_c = 25.0;
  // Both Udc and Rs known: the steady-state voltage and its limit can be
  // computed (VoltageV, UMaxV).
  bool HasVoltageLimit() const { return udc_v.has_value() && rs_ohm.has_value(); }
  // u_max = m Udc / sqrt(3): the linear range of space-vector PWM. NaN when
  // Udc is unknown (callers check HasVoltageLimit first).
  double UMaxV() const;
};

// Magnet temperature (docs/tables.md, "Magnet temperature"): the magnet
// flux linkage of permanent magnets falls with temperature, for NdFeB by
// about 0.1 %/K (remanence coefficient alpha_Br about -0.1 %/K; sintered
// NdFeB datasheets give -0.09 to -0.12 %/K). A table at magnet temperature
// T is computed from the calibration's flux map with psi_pm scaled to
//   psi_pm(T) = psi_pm(T_ref) (1 + alpha (T - T_ref)),
// i.e. psi_d shifted by (scale - 1) psi_d(0, 0) at every current, the
// inductances unchanged (the iron's saturation by the magnet is not
// modelled). alpha and T_ref must be the calibration's own (a measured
// or datasheet coefficient it states); none is invented. The linear
// reversible temperature coefficient of remanence is how magnet datasheets
// and IEC 60404-8-1 state it; psi_pm is proportional to the remanence.
struct MagnetTemperature {
  double alpha_per_k = 0;       // relative change of psi_pm per kelvin (e.g. -0.001)
  double reference_c = 25;      // temperature the calibration's flux map holds
  double at_c = 25;             // the table's magnet temperature
  // The spread (max - min) of the temperatures the flux map was recorded
  // at, K, where the calibration states it (written as a scalar).
  std::optional<double> reference_spread_k{};
  double Scale() const { return 1.0 + alpha_per_k * (at_c - reference_c); }
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
  std::string kind;    // "mtpa", "mtpv", "fw", "envelope"
  // "" (the default) or a tag that joins the kind in every label
  // (FLUXCAL_FW_UDC300V_ID_A, the A2L project and the C include guard):
  // the tables of a Udc axis (UdcTag) live side by side in one ECU build.
  // The generating envelope's tag starts with kGeneratingTag
  // (FLUXCAL_ENVELOPE_GENERATING_TORQUE_NM, ..._GENERATING_UDC300V_...), so
  // that it sits beside the motoring one too.
  std::string label_tag;
  // envelope: the generating limit (torque and power <= 0), written as the
  // scalar torque_sign = -1 (motoring: +1).
  bool envelope_generating = false;
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
  // Set when the table was computed at a stated magnet temperature
  // (TableSpec::magnet_temperature): written as scalars.
  std::optional<MagnetTemperature> magnet_temperature;
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

// Breakpoints (docs/tables.md): every axis is the multiples of a round
// step, 1, 2 or 5 x 10^k, within its range: the torque axes (MTPA rows, the
// FW map's first axis) within +-T_max (the limit torque at standstill,
// 0 included exactly), the FW speed axis within [0, speed_max_rpm], the
// MTPV flux axis within the fluxes it covers. The step is the smallest
// that gives at most `points` (`speed_points`) breakpoints: a count is a
// budget, "at most N", and the axis ends at the last multiple inside its
// range (the torque axis a step or less short of T_max, so that no row asks
// for more than the machine gives).
struct TableSpec {
  std::string kind = "mtpa";        // mtpa | mtpv | fw | envelope
  int points = 64;                  // at most this many rows of a curve / torque axis of the map
  int speed_points = 32;            // fw, envelope: at most this many speeds
  double speed_max_rpm = 6000.0;    // fw, envelope: speed axis range [0, max]
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
  // Unset: the model as it is. Set: psi_pm scaled to this magnet
  // temperature (MagnetScaledModel) before anything is computed.
  std::optional<MagnetTemperature> magnet_temperature;
  // "" or the tag joining the kind in every label (Table::label_tag).
  std::string label_tag;
  // envelope: the generating limit (negative torque and power) instead of
  // the motoring one (the report page draws both; `fluxcal export --table
  // envelope --generating`, ExportTable `generating`). Its labels carry
  // kGeneratingTag before label_tag. Only for kind envelope (the export
  // rule refuses it with any other table).
  bool envelope_generating = false;
};

// The label tag part of the generating envelope (Table::label_tag).
inline constexpr char kGeneratingTag[] = "generating";

double TorqueNm(const sim::MagneticModel& m, int pole_pairs, double id_a, double iq_a,
                double temperature_c = 25.0);
// Steady-state voltage magnitude at electrical speed w_e (NaN when Rs is
// unknown: callers check lim.HasVoltageLimit()).
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
// we_rad_s > 0 and a known voltage limit (lim.HasVoltageLimit()) the
// voltage limit |u| = u_max at that speed, labelled
// `voltage_label`. The fields are sampled over [id_lo_a, 0.6 i_max] x
// [-0.2 i_max, iq_hi_a], beyond the view (equal scaling widens one axis;
// the figure clips at its frame). With `generating` the generating half
// too: the fields over [-iq_hi_a, iq_hi_a], the circle's whole left half
// and negative torque levels (the report page draws both directions, as
// the tables hold both). Returns the circle's points (for a second circle
// drawn to scale).
struct PlaneCircle {
  std::vector<double> id_a, iq_a;
};
PlaneCircle DrawCurrentPlane(plot::Figure* f, const sim::MagneticModel& m, const MachineLimits& lim, double id_lo_a,
                             double iq_hi_a, double we_rad_s, const std::string& voltage_label,
                             bool generating = false);

// The breakpoints of an axis over [lo_value, hi_value]: the multiples of
// the smallest round step (1, 2 or 5 x 10^k) that gives at most
// `max_points` of them, at least 2; 0 among them whenever the range holds
// it. Each value is the double nearest its decimal (k m / 10^e, one
// rounding). InvalidArgument naming `flag` when the range is empty or no
// round step puts 2..max_points breakpoints into it.
absl::StatusOr<std::vector<double>> RoundBreakpoints(double lo_value, double hi_value, int max_points,
                                                     const std::string& flag = "--points");

// The torque-speed envelope (kind "envelope"): over round speeds in
// [0, speed_max_rpm] (at most speed_points), the largest motoring torque
// inside both the current and the voltage limit (MaxTorqueNm: the MTPA
// point below base speed, field weakening and MTPV above) and its
// operating point. Outputs id_a, iq_a (the point), torque_nm and power_w
// (= torque x mechanical speed); a speed at which no torque is available
// (beyond the machine's reach at this Udc) is flagged clamped, torque 0.
// With spec.envelope_generating the generating limit instead (torque and
// power negative; the resistive drop then helps). Needs the voltage limit
// (Udc and Rs), as the fw map.
//
// When `m` is a fit::Calibration, each cell's operating point is placed in
// its measured region (Calibration::RegionOf): `by_symmetry` and
// `extrapolated` flag what does not rest on measured data. Every cell's
// `not_positive_definite` comes from m.Inductance at its operating point.
// Errors: InvalidArgument (points, limits, kind; pole pairs or current
// limit not given; fw or envelope without Udc or Rs; a current limit above the
// measured one without allow_extrapolation), FailedPrecondition (mtpv: no
// MTPV point inside the current limit and allow_extrapolation not set).
// MTPA and MTPV need no Udc (their points do not depend on it); the file
// states Udc, Rs and u_max only when they were given.
absl::StatusOr<Table> BuildTable(const sim::MagneticModel& m, const MachineLimits& lim,
                                 const TableSpec& spec);

// Clamped cells of a table: how many of how many, and why, in words that
// name the limit that binds (the voltage limit at its Udc from some speed
// on, the current limit). A table with more than kMaxClampedShare of its
// cells clamped is refused by the export rule (tables/export_rule.h) unless
// asked for: it would tell an ECU mostly what the machine cannot do.
inline constexpr double kMaxClampedShare = 0.5;
struct ClampSummary {
  size_t cells = 0, clamped = 0;
  double share = 0;   // clamped / cells
  std::string why;    // empty when nothing is clamped
};
ClampSummary SummariseClamped(const Table& t);

// Canonical payload: for each axis then each output, its values as IEEE-754
// float64 little endian, in declaration order (docs/tables.md).
std::string PayloadBytes(const Table& t);
void Seal(Table* t);   // fills crc32 and sha256

// The export formats, the one list of their names (ParseFormat's): csv,
// json, h (C header), cdfx (ASAM CDF 2.0), dcm (DAMOS DCM 2.0), a2l (ASAM
// MCD-2 MC 1.71 description of the C header's arrays, tables/a2l.cc).
enum class Format { kCsv, kJson, kCHeader, kCdfx, kDcm, kA2l };
// InvalidArgument naming --format and the accepted names otherwise.
absl::StatusOr<Format> ParseFormat(const std::string& name);

// Labels, one home for every format: the DCM / CDFX label and A2L name of a
// field of a table ("FLUXCAL_FW_ID_A"), its C symbol (the C header's array
// or text variable, "fluxcal_fw_id_a"; macros are the label), the unit a
// name's suffix gives ("id_a" -> "A", "torque_nm" -> "Nm", "-" without
// one), the one sentence on the axis order every file states, and text
// made safe for a one-line comment.
std::string Label(const Table& t, const std::string& name);
std::string CSymbol(const Table& t, const std::string& name);
std::string UnitOf(const std::string& name);
std::string AxisOrder(const Table& t);
std::string OneLine(std::string s);

// Element type of the C header's value arrays (axes and outputs) and of
// the A2L's RECORD_LAYOUTs: binary64, binary32, or fixed point in a
// signed 16- or 32-bit integer (docs/tables.md, "Fixed point").
enum class CType { kDouble, kFloat, kInt16, kInt32 };
// "double" | "float" | "int16" | "int32"; InvalidArgument naming --ctype otherwise.
absl::StatusOr<CType> ParseCType(const std::string& name);
const char* CTypeName(CType ct);   // "double", "float", "int16", "int32"
int FixedPointBits(CType ct);      // 16, 32; 0 for the floating types

// The scale of one physical quantity (the axes and outputs of one unit) in
// an export: physical = lsb * raw + offset. The full scale is the smallest
// power of two that holds every value of the quantity in the table (its
// axes, outputs and scalars) at most kFixedPointFill of it: headroom for a
// calibration engineer's edits. Fixed point (bits 16 or 32): lsb =
// full_scale / 2^(bits - 1), a power of two, so that raw * lsb is exact and
// a value rounded to the nearest raw is off by at most lsb / 2; offset 0
// (signed types, ranges around 0); representable [-full_scale, full_scale -
// lsb]. Floating types (bits 0): lsb 0, the full scale only bounds the A2L
// limits.
inline constexpr double kFixedPointFill = 0.8;
// The smallest power of two f with max_abs <= kFixedPointFill * f (1 for 0).
double FullScale(double max_abs);
struct QuantityScale {
  std::string unit;                  // UnitOf: "A", "Nm", "rpm", "Wb", ...
  std::vector<std::string> arrays;   // the axes and outputs of this unit, in file order
  int bits = 0;                      // 16, 32; 0: floating
  double full_scale = 1;             // a power of two
  double lsb = 0;                    // full_scale / 2^(bits - 1); 0 when floating
  double offset = 0;                 // always 0
  double min_value = 0, max_value = 0;   // physical range: [-full_scale, full_scale - lsb]
};
// One per unit of the table's axes and outputs, in order of first use.
std::vector<QuantityScale> QuantityScales(const Table& t, CType ct);
// The scale of the axis or output `name` (nullptr when it has none).
const QuantityScale* ScaleOf(const std::vector<QuantityScale>& scales, const std::string& name);
// `values` as integers of `s`: each rounded to the nearest raw (half away
// from zero). A value whose nearest raw lies outside the signed `bits`-bit
// range is refused, never saturated: OutOfRange naming `what`, the index,
// the value and the range; InvalidArgument for a floating scale.
absl::StatusOr<std::vector<int64_t>> Quantize(const std::vector<double>& values, const QuantityScale& s,
                                              const std::string& what);

struct ExportOptions {
  // C header (h) and A2L element type of the value arrays; the other
  // formats write the values as decimals regardless.
  CType ctype = CType::kDouble;
};
struct Exported {
  std::string bytes;
  uint32_t payload_crc32 = 0;    // over the values (PayloadBytes), as written inside the file
  std::string payload_sha256;    // over the values (PayloadBytes), as written inside the file
  std::string file_sha256;       // over `bytes`: equals `sha256sum FILE` of the written file
  // h and a2l with a fixed-point ctype: the scale of each quantity, as the
  // file states it; empty otherwise.
  std::vector<QuantityScale> fixed_point;
};
// Errors: InvalidArgument (empty table, a non-finite value: named by field),
// OutOfRange (fixed point: a value the integer type cannot hold; cannot
// happen with the scales QuantityScales chooses, kept as the guard).
absl::StatusOr<Exported> Export(const Table& t, Format f, const ExportOptions& opt = {});

// SVG plots (drawn with plot/), the motoring half of the (id, iq) plane on
// equal axes: round-valued torque contours, the current limit circle (and
// the measured one where it differs), the voltage limit at a speed its
// legend states, and the tables' motoring rows; rows flagged clamped or
// extrapolated get their own markers.
// The MTPA table's figure: MTPA bold with a dot per row, the voltage limit
// at 1.5 x base speed (without Udc or Rs: none, and a note says why); the
// MTPV table (if given) thin, for reference.
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
// The envelope figure: torque and power versus speed, one curve per
// envelope table (one per Udc, labelled with its Udc), in two panels.
// Stretches whose operating points are extrapolated are dotted, those by
// symmetry dashed, measured ones solid (the report page's key); speeds with no torque (clamped)
// are left out of the curve and counted in a note.
std::string PlotEnvelopeSvg(const std::vector<Table>& envelopes);

// The label tag of a Udc-axis table: "udc300v", "udc312p5v" (a decimal
// point as 'p'), for Table::label_tag.
std::string UdcTag(double udc_v);

// `base` with its magnet flux scaled (MagnetTemperature above). The table
// cells' regions are still those of `base` when it is a fit::Calibration
// (BuildTable looks through the wrapper).
class MagnetScaledModel : public sim::MagneticModel {
 public:
  MagnetScaledModel(const sim::MagneticModel& base, const MagnetTemperature& t);
  sim::FluxLinkage Flux(double id_a, double iq_a, double temperature_c = 25.0) const override;
  sim::DifferentialInductance Inductance(double id_a, double iq_a, double temperature_c = 25.0) const override;
  void FluxAndInductance(double id_a, double iq_a, double temperature_c, sim::FluxLinkage* flux,
                         sim::DifferentialInductance* inductance) const override;
  const sim::MagneticModel& base() const { return base_; }
  const MagnetTemperature& temperature() const { return t_; }
 private:
  const sim::MagneticModel& base_;
  MagnetTemperature t_;
};

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TABLES_TABLES_H_
