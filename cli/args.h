// Minimal, strict flag parsing shared by the subcommands:
//   --name value | --name=value | --flag ; everything else is positional.
// Unknown flags are errors (a typo must not be silently ignored).
#ifndef FLUXCAL_CLI_ARGS_H_
#define FLUXCAL_CLI_ARGS_H_

#include <map>
#include <optional>
#include <set>
#include <string>
#include <string_view>
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

// One flag of a command, declared once: the parser accepts exactly these and
// `fluxcal COMMAND --help` lists them. help is one line and says the unit
// and the default ("default 50051", "A", ...).
struct FlagSpec {
  std::string name;        // without "--"
  std::string value;       // placeholder of the value ("FILE", "A"); empty: a switch
  std::string help;
};
using FlagSpecs = std::vector<FlagSpec>;
absl::StatusOr<ParsedArgs> ParseArgs(const std::vector<std::string>& args, const FlagSpecs& flags);
// flags without the named ones (a mode of a command that takes fewer).
FlagSpecs WithoutFlags(const FlagSpecs& flags, const std::set<std::string>& names);

// The flags many commands take, each said one way everywhere.
// --json: "print WHAT as one JSON document" (cli/command.h: exactly one).
FlagSpec JsonFlag(const std::string& what);
inline const FlagSpec kJsonFlag = JsonFlag("the result");
// --server ADDR of a command that only talks to the service.
inline const FlagSpec kServerFlag = {"server", "ADDR", "the service, HOST[:PORT] (default port 50051; required)"};
// --server ADDR of a command that works locally too: "USE, HOST[:PORT] ...".
FlagSpec ServerFlag(const std::string& use);
// --version N beside such a --server.
inline const FlagSpec kServerVersionFlag = {"version", "N", "with --server: calibration version (default the latest)"};
// --db URL of a command that only reads a store that exists.
inline const FlagSpec kExistingDbFlag = {"db", "URL",
                                         "the store: SQLite PATH or postgresql://... (required; must exist)"};
// --out FILE that may be "-" (CheckOutToStdout): "WHAT to write (required; - for stdout)".
FlagSpec OutFlag(const std::string& what);

// Prints "usage: USAGE" on stderr and returns 2 (the exit status of a usage error).
int UsageError(const std::string& usage);

// True if args ask for help (--help or -h where a flag may stand, i.e. not as
// the value of a flag that takes one).
bool WantsHelp(const std::vector<std::string>& args, const FlagSpecs& flags);

// The gRPC target for --server: HOST (port 50051), HOST:PORT, [V6]:PORT,
// [V6] or a bare IPv6 address (port 50051); "unix:", "dns:", "ipv4:" and
// "ipv6:" targets unchanged.
inline constexpr int kDefaultPort = 50051;
std::string ServerTarget(const std::string& server);

// "--out -": the output goes to stdout. Refuses (usage message naming both
// flags) "--out -" together with --json; "" if fine.
std::string CheckOutToStdout(const ParsedArgs& args, const std::string& out_flag = "out");
// Writes data to path, or to stdout for "-".
absl::Status WriteOutput(const std::string& path, std::string_view data);

// The one overwrite rule (docs/cli.md, "Files a command writes"): no command
// replaces a file that exists unless it is given --force. Every command that
// writes a file declares kForceFlag and calls CheckOverwrite for every path
// it will write, before any work (so a refusal costs nothing), and
// WriteNewOutput at the moment of writing. "-" (stdout) is never refused;
// an empty directory is not "existing output", a directory with files is.
inline const FlagSpec kForceFlag = {"force", "", "replace output files that exist (refused otherwise)"};
struct OutputPath {
  std::string flag;   // the flag that names it, without "--" ("out", "svg")
  std::string path;
};
// "" when every path may be written; else the refusal, naming the flag and
// the path: "flag --out: 'cal.json' exists; not overwritten (give --force
// to replace it)". A refusal exits 1 (the command was well formed).
std::string CheckOverwrite(const ParsedArgs& args, const std::vector<OutputPath>& outputs);
// CheckOverwrite for one path, then WriteOutput: FailedPrecondition with
// the refusal, or WriteOutput's status.
absl::Status WriteNewOutput(const ParsedArgs& args, const OutputPath& output, std::string_view data);

// The exit status of a refused request (docs/cli.md, "Exit status"): 2 when
// the status names a flag to give or correct (InvalidArgument whose message
// starts with "flag --" or "--"), 1 for everything else: bad input, a
// failed check, a table refused for what it would contain (the MTPV curve
// outside the current limit, mostly clamped cells), an existing output.
int ExitCodeFor(const absl::Status& status);

}  // namespace fluxcal::cli

#endif  // FLUXCAL_CLI_ARGS_H_
