// The recording-set reader's and writer's own parts (not a public API;
// nothing outside io/ includes this): the manifest parser (manifest.cc)
// with its message context, used by the set reader (recording_set.cc), and
// the path rule the writer (recording_set_write.cc) keeps too.
#ifndef FLUXCAL_IO_RECORDING_SET_INTERNAL_H_
#define FLUXCAL_IO_RECORDING_SET_INTERNAL_H_

#include <cstddef>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"

namespace fluxcal::io::internal {

// Best-effort line of `"key"` in the manifest text, so that messages can
// point at the offending line; falls back to line 1.
size_t LineOfKey(const std::string& text, const std::string& key, size_t start_line = 1);

// Context for manifest errors: display path + text for line lookup.
struct ManifestCtx {
  std::string path;
  std::string text;
  absl::Status Error(const std::string& field, const std::string& what,
                     size_t line = 0) const {
    if (line == 0) {
      const auto dot = field.find_last_of('.');
      std::string leaf = dot == std::string::npos ? field : field.substr(dot + 1);
      const auto br = leaf.find('[');
      if (br != std::string::npos) leaf = leaf.substr(0, br);
      line = LineOfKey(text, leaf);
    }
    return absl::InvalidArgumentError(
        absl::StrCat(path, ":", line, ": field '", field, "': ", what));
  }
};

absl::StatusOr<Manifest> ParseManifest(const ManifestCtx& ctx);

// The manifest as JSON (manifest.json's fields).
nlohmann::json ManifestToJson(const Manifest& m);

// A referenced file must stay inside the set directory.
bool IsSafeRelativePath(const std::string& p);

}  // namespace fluxcal::io::internal

#endif  // FLUXCAL_IO_RECORDING_SET_INTERNAL_H_
