// Flux maps as CSV grids, the way the field's tools exchange them: one row
// per (id, iq) node with the flux linkage psi_d, psi_q there (a measured map,
// an FEA export, motulator's and SyR-e's users' files).
//
// Conventions (as everywhere in fluxcal, docs/recording-format.md): dq frame
// on the rotor d (magnet) axis, amplitude-invariant Clarke, so currents are
// peak-valued space vectors in A and flux linkages in Wb (= V s);
// psi_d(0, 0) = psi_pm > 0.
//
// Reading: columns are found by header name, case-insensitively; accepted
// spellings (docs/fitting.md, "Flux maps in and out"):
//   id:    id_A, id, i_d, i_d_A        iq:    iq_A, iq, i_q, i_q_A
//   psi_d: psi_d_Vs, psi_d_Wb, psi_d, psid, Fd
//   psi_q: psi_q_Vs, psi_q_Wb, psi_q, psiq, Fq
//   symmetrised pair (FluxMapColumns::kSymmetrised only):
//          psi_d_sym_Vs, psi_d_sym_Wb, psi_d_sym and the same for q
// Other columns are ignored (their cells are not parsed). Lines starting
// with '#' before the header are skipped, as is a UTF-8 byte-order mark.
// The nodes may come in any order but must fill a rectangular grid exactly
// once: every id value with every iq value. Axis values compare exactly
// (-0 is 0): a map whose nodes are off their grid by rounding is reported as
// a missing node, never snapped.
#ifndef FLUXCAL_IO_FLUX_MAP_H_
#define FLUXCAL_IO_FLUX_MAP_H_

#include <cstddef>
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

struct FluxMap {
  std::vector<double> id_a, iq_a;     // strictly increasing axes
  // psi_*_wb[i][j] at (id_a[i], iq_a[j]).
  std::vector<std::vector<double>> psi_d_wb, psi_q_wb;
  std::string source;                 // file it was read from ("" if made in memory)

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
};

// Parses `text`, the contents of `display_path`. Errors are InvalidArgument
// naming file, line and field, e.g.
//   map.csv:41: field 'psi_d_Vs': expected a number, got 'x'
//   map.csv:1: field 'psi_q': missing column (accepted: ...; header has ...)
//   map.csv:569: field 'iq_A': duplicate node (id = -20 A, iq = 16 A), first on line 23
//   map.csv:71: field 'iq_A': missing node (id = -16 A, iq = 6 A): ...
// (a missing node's line is that of the nearest node of its id row).
absl::StatusOr<FluxMap> ParseFluxMapCsv(std::string_view text, const std::string& display_path,
                                        const FluxMapReadOptions& options = {});

// Reads and parses a file: NotFound if it cannot be read, InvalidArgument
// if larger than kMaxFluxMapBytes or malformed (as above).
absl::StatusOr<FluxMap> ReadFluxMapCsv(const std::string& path,
                                       const FluxMapReadOptions& options = {});

// InvalidArgument unless the axes are non-empty, finite and strictly
// increasing and both grids are id_a.size() x iq_a.size() of finite values.
absl::Status ValidateFluxMap(const FluxMap& map);

// The CSV text: header `id_A,iq_A,psi_d_Vs,psi_q_Vs`, one node per line, id
// slowest, every number with 17 significant digits, so that reading it back
// gives the same doubles. InvalidArgument if ValidateFluxMap fails.
absl::StatusOr<std::string> FluxMapCsv(const FluxMap& map);
// FluxMapCsv written atomically (io/csv.h, WriteFileAtomically).
absl::Status WriteFluxMapCsv(const std::string& path, const FluxMap& map);

}  // namespace fluxcal::io

#endif  // FLUXCAL_IO_FLUX_MAP_H_
