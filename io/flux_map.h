// Flux maps as CSV grids, the way the field's tools exchange them: one row
// per (id, iq) node with the flux linkage psi_d, psi_q there (a measured map,
// an FEA export, motulator's and SyR-e's users' files).
//
// Conventions (as everywhere in fluxcal, docs/recording-format.md): dq frame
// on the rotor d (magnet) axis, amplitude-invariant Clarke, so currents are
// peak-valued space vectors in A and flux linkages in Wb (= V s);
// psi_d(0, 0) = psi_pm > 0. A FluxMap in memory is always in this
// convention; reading converts the file's (FluxMapConvention below) and
// then refuses a map that is not plausible (io/plausibility.h).
//
// Reading: columns are found by header name, case-insensitively; accepted
// spellings (docs/fitting.md, "Flux maps in and out"):
//   id:    id_A, id, i_d, i_d_A        iq:    iq_A, iq, i_q, i_q_A
//   psi_d: psi_d_Vs, psi_d_Wb, psi_d_mVs, psi_d_mWb, psi_d, psid, Fd
//   psi_q: psi_q_Vs, psi_q_Wb, psi_q_mVs, psi_q_mWb, psi_q, psiq, Fq
//   symmetrised pair (FluxMapColumns::kSymmetrised only):
//          psi_d_sym_Vs, psi_d_sym_Wb, psi_d_sym_mVs, psi_d_sym_mWb,
//          psi_d_sym and the same for q
// Other columns are ignored (their cells are not parsed). Lines starting
// with '#' before the header are skipped, as is a UTF-8 byte-order mark.
// The nodes may come in any order but must fill a rectangular grid exactly
// once: every id value with every iq value. Axis values compare exactly
// (-0 is 0): a map whose nodes are off their grid by rounding is reported as
// a missing node, never snapped.
#ifndef FLUXCAL_IO_FLUX_MAP_H_
#define FLUXCAL_IO_FLUX_MAP_H_

#include <cstddef>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace fluxcal::io {

// Bounds on what a reader accepts: a 1000 x 1000 map is far finer than any
// measurement or FEA sweep; beyond that the file is not a flux map.
inline constexpr size_t kMaxFluxMapRows = 1'000'000;
inline constexpr size_t kMaxFluxMapBytes = size_t{64} << 20;   // 64 MiB

struct FluxMapPoint {
  double id_a = 0, iq_a = 0, psi_d_wb = 0, psi_q_wb = 0;
};

// ---- Conventions of the field's tools --------------------------------------

// Which dq axes the file's id, iq, psi_d, psi_q are on.
enum class FluxMapAxes {
  // Detected from the node at zero current, where the only flux is the
  // magnet's: on +d -> kFluxcal, on -q -> kSyre. Anything else (no node at
  // (0, 0), no magnet flux there, the flux on +q, -d or between the axes)
  // is refused, naming the likely cause: never guessed.
  kAuto,
  // fluxcal: d = magnet axis, psi_d(0, 0) = psi_pm > 0.
  kFluxcal,
  // motulator: the same axes and scaling as fluxcal (its machine models use
  // peak-valued space vectors with the PM flux on d, motulator's
  // drive/model/_machine.py), so the file is taken as it is.
  kMotulator,
  // SyR-e: d = the high-permeance (reluctance) axis, the magnets on -q
  // (psi_q(0, 0) = -psi_pm). fluxcal's d is SyR-e's -q, and fluxcal's q,
  // 90 electrical degrees ahead of it, is SyR-e's +d:
  //   id = -Iq, iq = Id, psi_d = -Fq, psi_q = Fd
  // for currents and fluxes alike (a rotation of the frame by -90 degrees:
  // the torque 3/2 p (psi_d iq - psi_q id) is unchanged). motulator imports
  // SyR-e's maps with exactly this map (model/sm/_flux_maps.py,
  // import_syre_data: i_d = -Iq, i_q = Id, psi_d = -Fq, psi_q = Fd).
  kSyre,
};

// Scaling of the dq space vector relative to the phase quantities, for a
// balanced sinusoidal set of peak amplitude X in each phase:
//   kPeak            amplitude-invariant Clarke, x = 2/3 (xa + a xb + a^2 xc):
//                    |x| = X (fluxcal's, motulator's and SyR-e's);
//   kRms             rms-valued dq quantities: |x| = X / sqrt(2), so the
//                    peak value is sqrt(2) |x|;
//   kPowerInvariant  x = sqrt(2/3) (xa + a xb + a^2 xc): |x| = sqrt(3/2) X,
//                    so the peak value is sqrt(2/3) |x|.
enum class AmplitudeScaling { kPeak, kRms, kPowerInvariant };

// Unit of the flux columns. kFromHeader: the psi columns' suffix says it
// (_Wb, _Vs: Wb; _mWb, _mVs: mWb); without a suffix (psi_d, Fd) Wb.
enum class FluxUnit { kFromHeader, kWb, kVs, kMWb, kMVs };

struct FluxMapConvention {
  FluxMapAxes axes = FluxMapAxes::kAuto;
  AmplitudeScaling current = AmplitudeScaling::kPeak;
  AmplitudeScaling flux = AmplitudeScaling::kPeak;
  // Overrides the header's unit suffix (a file may say psi_d_Vs and hold
  // mWb); the override is noted in AppliedFluxMapConvention::detail.
  FluxUnit flux_unit = FluxUnit::kFromHeader;
};

// Names as the CLI flags and JSON spell them: "auto", "fluxcal",
// "motulator", "syre"; "peak", "rms", "power-invariant"; "header", "Wb",
// "Vs", "mWb", "mVs". *FromName returns nullopt for anything else (the
// unit names match case-sensitively: mWb is not MWb).
const char* Name(FluxMapAxes axes);
const char* Name(AmplitudeScaling scaling);
const char* Name(FluxUnit unit);
std::optional<FluxMapAxes> FluxMapAxesFromName(std::string_view name);
std::optional<AmplitudeScaling> AmplitudeScalingFromName(std::string_view name);
std::optional<FluxUnit> FluxUnitFromName(std::string_view name);

// What reading a file applied (the user sees it: `fluxcal fit --map` and
// `fluxcal compare` print it on stderr and in --json).
struct AppliedFluxMapConvention {
  FluxMapAxes axes = FluxMapAxes::kFluxcal;   // never kAuto
  bool axes_detected = false;                 // from the zero-current node
  AmplitudeScaling current = AmplitudeScaling::kPeak;
  AmplitudeScaling flux = AmplitudeScaling::kPeak;
  FluxUnit flux_unit = FluxUnit::kWb;         // never kFromHeader
  std::string flux_unit_source;               // "header", "flag" or "assumed"
  // file value x factor = fluxcal value (after the axes' signs).
  double current_factor = 1.0, flux_factor = 1.0;
  // Why: e.g. "magnet flux 0.444 Wb on -q at zero current (line 285)".
  std::string detail;
  // One line: "axes syre (detected: ...): id = -Iq, iq = Id, psi_d = -Fq,
  // psi_q = Fd; currents peak; flux peak, Wb (header)".
  std::string Describe() const;
};

struct FluxMap {
  std::vector<double> id_a, iq_a;     // strictly increasing axes
  // psi_*_wb[i][j] at (id_a[i], iq_a[j]).
  std::vector<std::vector<double>> psi_d_wb, psi_q_wb;
  std::string source;                 // file it was read from ("" if made in memory)
  AppliedFluxMapConvention convention;   // what reading applied (made in memory: fluxcal's)

  size_t size() const { return id_a.size() * iq_a.size(); }
  // Every node, id slowest (the order WriteFluxMapCsv writes).
  std::vector<FluxMapPoint> Points() const;
};

// Which flux columns to read: the raw pair (default), or the pair a
// publisher symmetrised about iq = 0 (psi_d_sym_*, psi_q_sym_*), which must
// then be present.
enum class FluxMapColumns { kRaw, kSymmetrised };

struct FluxMapReadOptions {
  FluxMapColumns columns = FluxMapColumns::kRaw;
  FluxMapConvention convention;
};

// Thresholds of the reader's checks (flux_map.cc says why these values).
// The zero-current flux is "on an axis" within this angle of it:
inline constexpr double kFluxMapAxisToleranceDeg = 10.0;
// and "no magnet flux" below this fraction of the map's largest |psi|:
inline constexpr double kFluxMapNoMagnetFraction = 0.02;

// Parses `text`, the contents of `display_path`, converts it from
// options.convention into fluxcal's and checks it is plausible. Errors are
// InvalidArgument naming file, line and field, e.g.
//   map.csv:41: field 'psi_d_Vs': expected a number, got 'x'
//   map.csv:1: field 'psi_q': missing column (accepted: ...; header has ...)
//   map.csv:569: field 'iq_A': duplicate node (id = -20 A, iq = 16 A), first on line 23
//   map.csv:71: field 'iq_A': missing node (id = -16 A, iq = 6 A): ...
// (a missing node's line is that of the nearest node of its id row), and
// for a map that reads but is not plausible, with the likely cause:
//   map.csv:285: field 'psi_d_Vs': psi_pm 444 Wb (the flux at zero current,
//     read in Wb) is above the 10 Wb of a plausible machine: is the flux in
//     mWb? give --units mWb
//   map.csv:285: field 'Fq': the magnet lies on the -q axis (...): a SyR-e
//     map? give --convention syre
//   map.csv:285: field 'psi_q_Vs': the psi_d and psi_q columns look
//     exchanged: the magnet flux lies on +q at zero current (...)
//   map.csv:1: field 'psi_d_Vs': no node at id = iq = 0: the axes cannot be
//     detected; give --convention fluxcal|motulator|syre
//   map.csv:1: field 'psi_d_Vs': differential inductance L_dd = dpsi_d/did
//     44.3 H (median of the map's differences) outside [1e-7, 1) H: ...
// The checks, in this order (docs/fitting.md): currents within +-10 kA;
// |psi| at most 10 Wb (psi_pm when the map has a zero-current node); the
// axes (the zero-current flux on the axis the convention puts the magnet
// on, or no magnet flux there with an explicit convention); the mirror
// symmetry of a synchronous machine (psi_d even in iq, psi_q odd) where the
// map has nodes at +-iq; the medians of the map's own differential
// inductances dpsi_d/did and dpsi_q/diq within [1e-7, 1) H.
absl::StatusOr<FluxMap> ParseFluxMapCsv(std::string_view text, const std::string& display_path,
                                        const FluxMapReadOptions& options = {});

// Reads and parses a file: NotFound if it cannot be read, InvalidArgument
// if larger than kMaxFluxMapBytes or malformed (as above).
absl::StatusOr<FluxMap> ReadFluxMapCsv(const std::string& path,
                                       const FluxMapReadOptions& options = {});

// InvalidArgument unless the axes are non-empty, finite and strictly
// increasing and both grids are id_a.size() x iq_a.size() of finite values.
absl::Status ValidateFluxMap(const FluxMap& map);

// The CSV text, in fluxcal's convention: header `id_A,iq_A,psi_d_Vs,psi_q_Vs`,
// one node per line, id slowest, every number with 17 significant digits, so that reading it back
// gives the same doubles. InvalidArgument if ValidateFluxMap fails.
absl::StatusOr<std::string> FluxMapCsv(const FluxMap& map);
// FluxMapCsv written atomically (io/csv.h, WriteFileAtomically).
absl::Status WriteFluxMapCsv(const std::string& path, const FluxMap& map);

}  // namespace fluxcal::io

#endif  // FLUXCAL_IO_FLUX_MAP_H_
