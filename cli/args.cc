#include "cli/args.h"

#include <cerrno>
#include <cmath>
#include <cstdlib>

#include "absl/strings/str_cat.h"

namespace fluxcal::cli {

std::optional<std::string> ParsedArgs::Get(const std::string& flag) const {
  auto it = values.find(flag);
  if (it == values.end()) return std::nullopt;
  return it->second;
}

absl::StatusOr<std::optional<double>> ParsedArgs::GetDouble(
    const std::string& flag) const {
  auto v = Get(flag);
  if (!v) return std::optional<double>();
  char* end = nullptr;
  errno = 0;
  const double x = std::strtod(v->c_str(), &end);
  if (v->empty() || *end != '\0' || errno != 0 || !std::isfinite(x)) {
    return absl::InvalidArgumentError(
        absl::StrCat("flag --", flag, ": expected a finite number, got '", *v, "'"));
  }
  return std::optional<double>(x);
}

absl::StatusOr<ParsedArgs> ParseArgs(const std::vector<std::string>& args,
                                     const std::set<std::string>& value_flags,
                                     const std::set<std::string>& switch_flags) {
  ParsedArgs out;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a.size() > 2 && a.rfind("--", 0) == 0) {
      std::string name = a.substr(2), value;
      bool has_value = false;
      if (auto eq = name.find('='); eq != std::string::npos) {
        value = name.substr(eq + 1);
        name = name.substr(0, eq);
        has_value = true;
      }
      if (switch_flags.count(name)) {
        if (has_value) {
          return absl::InvalidArgumentError(
              absl::StrCat("flag --", name, " takes no value"));
        }
        out.switches.insert(name);
      } else if (value_flags.count(name)) {
        if (!has_value) {
          if (i + 1 >= args.size()) {
            return absl::InvalidArgumentError(
                absl::StrCat("flag --", name, " needs a value"));
          }
          value = args[++i];
        }
        out.values[name] = value;
      } else {
        return absl::InvalidArgumentError(absl::StrCat("unknown flag --", name));
      }
    } else {
      out.positional.push_back(a);
    }
  }
  return out;
}

}  // namespace fluxcal::cli
