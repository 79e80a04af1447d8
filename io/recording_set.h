// Recording sets, format version 1 (`fluxcal.recording.v1`), exactly as
// specified in shared/specs/recording-format.md (copied to
// docs/recording-format.md). SI units everywhere; names carry their unit.
//
// Conventions (the same everywhere in fluxcal):
//   theta_e_rad: electrical angle of the rotor d axis from the phase-a axis,
//     counter-clockwise positive.
//   Clarke, amplitude invariant: i_alpha = (2 ia - ib - ic)/3,
//     i_beta = (ib - ic)/sqrt(3).
//   Park: id + j iq = (i_alpha + j i_beta) exp(-j theta_e).
//   Machine (motor convention): ud = Rs id + dpsi_d/dt - w psi_q,
//     uq = Rs iq + dpsi_q/dt + w psi_d;  T = 1.5 p (psi_d iq - psi_q id).
#ifndef FLUXCAL_IO_RECORDING_SET_H_
#define FLUXCAL_IO_RECORDING_SET_H_

#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace fluxcal::io {

inline constexpr char kRecordingFormatV1[] = "fluxcal.recording.v1";

struct MotorNominal {
  int pole_pairs = 0;                  // required
  std::optional<double> rs_ohm;        // nominal (datasheet) value
  std::optional<double> psi_pm_wb;     // nominal (datasheet) value
  // fluxcal's compatible extension (docs/recording-format.md, "Magnet
  // temperature coefficient"): the relative change of psi_pm per kelvin of
  // magnet temperature (NdFeB about -0.0011 /K), within
  // [kMinPsiPmTempCoeffPerK, kMaxPsiPmTempCoeffPerK].
  std::optional<double> psi_pm_temp_coeff_per_k;
};

// The range a stated psi_pm temperature coefficient must lie in, 1/K:
// ferrite about -0.002, NdFeB -0.0009 .. -0.0012, SmCo -0.0003 .. -0.0004
// (remanence coefficients of magnet datasheets); wider than any magnet
// material, narrow enough to catch a value in %/K (-0.11) or a sign slip.
inline constexpr double kMinPsiPmTempCoeffPerK = -0.005;
inline constexpr double kMaxPsiPmTempCoeffPerK = 0.002;

struct DriveInfo {
  std::optional<double> udc_v;
  std::optional<double> f_pwm_hz;
  double f_sample_hz = 0.0;            // required
  std::optional<double> dead_time_s;
  std::optional<bool> dead_time_compensated;
};

struct InjectionInfo {
  std::string type;                    // "rotating"
  double amplitude_v = 0.0;
  double frequency_hz = 0.0;
};

struct PointSpec {
  std::string id;                      // e.g. "p000"
  std::string file;                    // relative to the set root
  double id_ref_a = 0.0;
  double iq_ref_a = 0.0;
  double speed_rpm = 0.0;
  std::optional<double> temperature_c;
};

struct Manifest {
  std::string format = kRecordingFormatV1;
  std::string serial;
  MotorNominal motor;
  DriveInfo drive;
  std::optional<InjectionInfo> injection;  // required when points present
  std::vector<PointSpec> points;
  std::optional<std::string> steady_state;  // relative file name
  std::optional<std::string> hf_results;    // relative file name
};

// One points/<id>.csv: equally spaced samples at drive.f_sample_hz.
// ualpha/ubeta_ref_v: the command sent at this sample, applied by the
// inverter during the following PWM period. udc_v is NaN where the cell was
// empty (then drive.udc_v holds; see EffectiveUdc()).
struct Waveform {
  std::vector<double> t_s;
  std::vector<double> ia_a, ib_a, ic_a;
  std::vector<double> theta_e_rad;
  std::vector<double> ualpha_ref_v, ubeta_ref_v;
  std::vector<double> udc_v;
  size_t size() const { return t_s.size(); }
};

struct SteadyStateRow {
  double id_a = 0, iq_a = 0, speed_rpm = 0, ud_ref_v = 0, uq_ref_v = 0;
  std::optional<double> torque_nm;
  std::optional<double> temperature_c;
  // What the bench could hold over the row's averaging window, the
  // compatible extension "Rows a bench could not hold" of
  // docs/recording-format.md (absent: column not in the file, or cell empty):
  //   current_ripple_a: RMS of the measured dq current vector's deviation
  //     from its own mean over the window, A (>= 0);
  //   voltage_limited_share: share of the window's control periods in which
  //     the modulator limited the voltage command, 0..1;
  //   controller_saturated_share: share of the window's control periods in
  //     which the current controller's output or integrator sat at a limit
  //     (clamped, anti-windup acting), 0..1.
  std::optional<double> current_ripple_a{};
  std::optional<double> voltage_limited_share{};
  std::optional<double> controller_saturated_share{};
};

struct HfResultRow {
  double id_a = 0, iq_a = 0, speed_rpm = 0, ld_h = 0, lq_h = 0;
  std::optional<double> ldq_h;
  std::optional<double> temperature_c;
};

struct RecordingSet {
  std::string root_dir;                // directory the set was read from
  Manifest manifest;
  std::vector<Waveform> waveforms;     // parallel to manifest.points
  std::vector<SteadyStateRow> steady_state;
  std::vector<HfResultRow> hf_results;
};

// Reads and strictly validates a set. Errors (never a crash, never a silent
// default) name the file, the line and the field, e.g.
//   set/points/p003.csv:41: field 'ia_a': expected a number, got 'x'
// Returns InvalidArgument for malformed content, NotFound for a missing
// manifest or referenced file.
absl::StatusOr<RecordingSet> ReadRecordingSet(const std::string& dir);

// A recording set held in memory: file name relative to the set root ->
// contents. A set that arrives over the network is read from here and never
// written to disk.
using RecordingFiles = std::map<std::string, std::string>;

inline constexpr size_t kMaxRecordingFileNameBytes = 255;
inline constexpr int kMaxRecordingFileDepth = 4;

// A file name as a client may send it: 1..255 bytes of '/'-separated
// components, each of A-Z a-z 0-9 - _ . and none empty, "." or ".."; no
// leading '/'; at most 4 levels. So a name can never reach outside a
// directory, carry a control character or a newline. InvalidArgument names
// the (escaped) file.
absl::Status ValidateRecordingFileName(std::string_view name);

// ReadRecordingSet over files in memory. Every name is checked with
// ValidateRecordingFileName first; messages name files as
// "<display_root>/<name>" (just "<name>" when display_root is empty).
absl::StatusOr<RecordingSet> ReadRecordingSetFromFiles(const RecordingFiles& files,
                                                       const std::string& display_root);

// Parses only manifest.json (validated as above).
absl::StatusOr<Manifest> ReadManifest(const std::string& manifest_path);

// Writes a set (manifest, waveforms, steady_state.csv, hf_results.csv as
// present) into dir, creating it. Numbers are written with enough digits to
// round-trip the physics (not necessarily bit-exact).
absl::Status WriteRecordingSet(const std::string& dir, const RecordingSet& set);

// Serial rule: 1 to 64 characters of A-Z a-z 0-9 - _ . (the contract's
// rule), and not only dots ("." and ".." name directories, not motors).
bool IsValidSerial(const std::string& serial);

// Standalone readers/writers of the optional tables (same validation).
// WriteSteadyStateCsv writes the extension columns (current_ripple_a,
// voltage_limited_share, controller_saturated_share) only when some row
// has one of them, so a set without them is written exactly as the base
// format's.
absl::StatusOr<std::vector<SteadyStateRow>> ReadSteadyStateCsv(const std::string& path);
absl::StatusOr<std::vector<HfResultRow>> ReadHfResultsCsv(const std::string& path);
absl::Status WriteHfResultsCsv(const std::string& path, const std::vector<HfResultRow>& rows);
absl::Status WriteSteadyStateCsv(const std::string& path,
                                 const std::vector<SteadyStateRow>& rows);

// DC-link voltage at a sample: the row's udc_v, else drive.udc_v, else NaN.
double EffectiveUdc(const RecordingSet& set, size_t point, size_t sample);

}  // namespace fluxcal::io

#endif  // FLUXCAL_IO_RECORDING_SET_H_
