// Minimal, strict flag parsing shared by the subcommands:
//   --name value | --name=value | --flag ; everything else is positional.
// Unknown flags are errors (a typo must not be silently ignored).
#ifndef FLUXCAL_CLI_ARGS_H_
#define FLUXCAL_CLI_ARGS_H_

#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace fluxcal::cli {

struct ParsedArgs {
  std::vector<std::string> positional;
  std::map<std::string, std::string> values;   // flags with a value
  std::set<std::string> switches;              // boolean flags present

  bool Has(const std::string& flag) const {
    return switches.count(flag) > 0 || values.count(flag) > 0;
  }
  std::optional<std::string> Get(const std::string& flag) const;
  // Parses a double; InvalidArgument naming the flag on failure.
  absl::StatusOr<std::optional<double>> GetDouble(const std::string& flag) const;
};

// value_flags: flags that take a value (without "--"); switch_flags: boolean.
absl::StatusOr<ParsedArgs> ParseArgs(const std::vector<std::string>& args,
                                     const std::set<std::string>& value_flags,
                                     const std::set<std::string>& switch_flags);

}  // namespace fluxcal::cli

#endif  // FLUXCAL_CLI_ARGS_H_
