// `fluxcal` subcommand registry. Each subcommand lives in cli/cmd_<name>.cc
// and registers itself with FLUXCAL_REGISTER_COMMAND, so adding a command
// touches no shared file. Conventions for every command:
//   - results on stdout; progress and logs on stderr;
//   - `--json` prints exactly one JSON document on stdout;
//   - exit 0 on success, 1 on bad input/validation (message on stderr naming
//     file, line and field), 2 on usage errors.
#ifndef FLUXCAL_CLI_COMMAND_H_
#define FLUXCAL_CLI_COMMAND_H_

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace fluxcal::cli {

// args excludes the program and subcommand names.
using CommandFn = std::function<int(const std::vector<std::string>& args)>;

struct Command {
  std::string name;
  std::string summary;   // one line for `fluxcal help`
  CommandFn run;
};

std::map<std::string, Command>& CommandRegistry();

struct CommandRegistrar {
  CommandRegistrar(std::string name, std::string summary, CommandFn fn) {
    CommandRegistry()[name] = Command{name, std::move(summary), std::move(fn)};
  }
};

}  // namespace fluxcal::cli

#define FLUXCAL_CLI_CONCAT_INNER(a, b) a##b
#define FLUXCAL_CLI_CONCAT(a, b) FLUXCAL_CLI_CONCAT_INNER(a, b)
#define FLUXCAL_REGISTER_COMMAND(name, summary, fn)                  \
  static ::fluxcal::cli::CommandRegistrar FLUXCAL_CLI_CONCAT(        \
      fluxcal_cli_registrar_, __LINE__)(name, summary, fn)

#endif  // FLUXCAL_CLI_COMMAND_H_
