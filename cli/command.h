// `fluxcal` subcommand registry. Each subcommand lives in cli/cmd_<name>.cc
// and registers itself with FLUXCAL_REGISTER_COMMAND, so adding a command
// touches no shared file. Conventions for every command:
//   - results on stdout; progress and logs on stderr;
//   - `--json` prints exactly one JSON document on stdout;
//   - exit 0 on success, 1 on bad input/validation (message on stderr naming
//     file, line and field), 2 on usage errors;
//   - every flag is declared once, with a one-line help, in a FlagSpecs list
//     that both ParseArgs and `fluxcal COMMAND --help` use (cli/main.cc
//     answers --help / -h and `fluxcal help COMMAND` before the command runs);
//   - flags are parsed before any work, so a bad flag costs nothing.
#ifndef FLUXCAL_CLI_COMMAND_H_
#define FLUXCAL_CLI_COMMAND_H_

#include <functional>
#include <map>
#include <string>
#include <vector>

#include "cli/args.h"

namespace fluxcal::cli {

// args excludes the program and subcommand names.
using CommandFn = std::function<int(const std::vector<std::string>& args)>;

struct Command {
  std::string name;
  std::string summary;   // one line for `fluxcal help`
  CommandFn run;
  std::string usage;     // "fluxcal NAME ARGS [flags]" lines, without "usage: "
  FlagSpecs flags;       // every flag the command accepts
  bool server_client = false;   // takes --server: the client flags apply
};

std::map<std::string, Command>& CommandRegistry();

struct CommandRegistrar {
  CommandRegistrar(std::string name, std::string summary, CommandFn fn, std::string usage = "",
                   FlagSpecs flags = {}) {
    bool server_client = false;
    for (const auto& f : flags) server_client = server_client || f.name == "server";
    CommandRegistry()[name] = Command{name, std::move(summary), std::move(fn), std::move(usage), std::move(flags),
                                      server_client};
  }
};

}  // namespace fluxcal::cli

#define FLUXCAL_CLI_CONCAT_INNER(a, b) a##b
#define FLUXCAL_CLI_CONCAT(a, b) FLUXCAL_CLI_CONCAT_INNER(a, b)
// FLUXCAL_REGISTER_COMMAND(name, summary, fn, usage, flags)
#define FLUXCAL_REGISTER_COMMAND(name, summary, ...)                 \
  static ::fluxcal::cli::CommandRegistrar FLUXCAL_CLI_CONCAT(        \
      fluxcal_cli_registrar_, __LINE__)(name, summary, __VA_ARGS__)

#endif  // FLUXCAL_CLI_COMMAND_H_
