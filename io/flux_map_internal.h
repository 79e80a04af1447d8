// The flux-map reader's own parts (not a public API; nothing outside io/
// includes this): what the parser (flux_map_parse.cc) hands to the
// convention and plausibility checks (flux_map_conform.cc), and the
// message helpers both use.
#ifndef FLUXCAL_IO_FLUX_MAP_INTERNAL_H_
#define FLUXCAL_IO_FLUX_MAP_INTERNAL_H_

#include <cstddef>
#include <map>
#include <string>
#include <string_view>
#include <utility>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "io/flux_map.h"

namespace fluxcal::io::internal {

enum Role { kId = 0, kIq, kPsiD, kPsiQ, kRoles };

// One node as the file wrote it, with its line for messages.
struct Node {
  double psi_d_wb = 0, psi_q_wb = 0;
  size_t line = 0;
};
using Nodes = std::map<std::pair<double, double>, Node>;   // by (id, iq) as written

// Where the messages about a whole map point: the file, its header line and
// the file's own column names.
struct Header {
  std::string path;
  size_t line = 1;
  std::string col[kRoles];
};

// "path:line: field 'field': what", INVALID_ARGUMENT.
absl::Status FieldError(const std::string& path, size_t line, std::string_view field, const std::string& what);
inline absl::Status MapError(const Header& h, size_t line, std::string_view field, const std::string& what) {
  return FieldError(h.path, line, field, what);
}
// A cell or header echoed in a message: at most 40 bytes, escaped.
std::string Shorten(std::string_view s);
// A current or flux value in a message: enough digits to tell nodes apart.
std::string Num(double x);

// `raw` (the file's axes and numbers, a full grid; `nodes` the same with
// their lines) in fluxcal's convention, or the reason it cannot be one.
absl::StatusOr<FluxMap> Conform(const FluxMap& raw, const Nodes& nodes, const Header& h,
                                const FluxMapConvention& conv);

}  // namespace fluxcal::io::internal

#endif  // FLUXCAL_IO_FLUX_MAP_INTERNAL_H_
