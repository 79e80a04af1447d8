#include "cli/args.h"

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "io/csv.h"

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

absl::StatusOr<ParsedArgs> ParseArgs(const std::vector<std::string>& args, const FlagSpecs& flags) {
  std::set<std::string> value_flags, switch_flags;
  for (const auto& f : flags) (f.value.empty() ? switch_flags : value_flags).insert(f.name);
  return ParseArgs(args, value_flags, switch_flags);
}

FlagSpecs WithoutFlags(const FlagSpecs& flags, const std::set<std::string>& names) {
  FlagSpecs out;
  for (const auto& f : flags) {
    if (!names.count(f.name)) out.push_back(f);
  }
  return out;
}

FlagSpec JsonFlag(const std::string& what) { return {"json", "", "print " + what + " as one JSON document"}; }

FlagSpec ServerFlag(const std::string& use) {
  return {"server", "ADDR", absl::StrCat(use, ", HOST[:PORT] (default port ", kDefaultPort, ")")};
}

FlagSpec OutFlag(const std::string& what) { return {"out", "FILE", what + " to write (required; - for stdout)"}; }

int UsageError(const std::string& usage) {
  std::fprintf(stderr, "usage: %s\n", usage.c_str());
  return 2;
}

bool WantsHelp(const std::vector<std::string>& args, const FlagSpecs& flags) {
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& a = args[i];
    if (a == "--help" || a == "-h") return true;
    if (a.size() > 2 && a.rfind("--", 0) == 0 && a.find('=') == std::string::npos) {
      for (const auto& f : flags) {
        if (!f.value.empty() && a.substr(2) == f.name) {
          ++i;   // its value, whatever it looks like
          break;
        }
      }
    }
  }
  return false;
}

std::string ServerTarget(const std::string& server) {
  for (const char* scheme : {"unix:", "unix-abstract:", "dns:", "ipv4:", "ipv6:", "vsock:"}) {
    if (server.rfind(scheme, 0) == 0) return server;
  }
  const std::string port = absl::StrCat(":", kDefaultPort);
  if (server.empty()) return server;
  if (server[0] == '[') {
    const auto close = server.find(']');
    if (close != std::string::npos && close + 1 == server.size()) return server + port;
    return server;   // [v6]:PORT (or malformed: gRPC says so)
  }
  const auto colons = std::count(server.begin(), server.end(), ':');
  if (colons == 0) return server + port;
  if (colons > 1) return "[" + server + "]" + port;   // a bare IPv6 address
  return server;
}

std::string CheckOutToStdout(const ParsedArgs& args, const std::string& out_flag) {
  if (args.Get(out_flag).value_or("") == "-" && args.Has("json")) {
    return absl::StrCat("--", out_flag, " - and --json both want stdout: give --", out_flag,
                        " FILE with --json, or drop --json");
  }
  return "";
}

absl::Status WriteOutput(const std::string& path, std::string_view data) {
  if (path != "-") return io::WriteFileAtomically(path, data);
  if (std::fwrite(data.data(), 1, data.size(), stdout) != data.size() || std::fflush(stdout) != 0) {
    return absl::DataLossError("cannot write to stdout");
  }
  return absl::OkStatus();
}

std::string CheckOverwrite(const ParsedArgs& args, const std::vector<OutputPath>& outputs) {
  if (args.Has("force")) return "";
  namespace fs = std::filesystem;
  for (const auto& o : outputs) {
    if (o.path.empty() || o.path == "-") continue;
    std::error_code ec;
    const fs::file_status st = fs::symlink_status(o.path, ec);
    if (ec || !fs::exists(st)) continue;
    if (fs::is_directory(st) && fs::is_empty(o.path, ec) && !ec) continue;
    return absl::StrCat("flag --", o.flag, ": '", o.path, "' exists",
                        fs::is_directory(st) ? " and is not empty" : "",
                        "; not overwritten (give --force to replace it)");
  }
  return "";
}

absl::Status WriteNewOutput(const ParsedArgs& args, const OutputPath& output, std::string_view data) {
  if (std::string refusal = CheckOverwrite(args, {output}); !refusal.empty()) {
    return absl::FailedPreconditionError(refusal);
  }
  return WriteOutput(output.path, data);
}

int ExitCodeFor(const absl::Status& status) {
  if (status.ok()) return 0;
  const std::string m(status.message());
  const bool names_flag = m.rfind("flag --", 0) == 0 || m.rfind("--", 0) == 0;
  return absl::IsInvalidArgument(status) && names_flag ? 2 : 1;
}

}  // namespace fluxcal::cli
