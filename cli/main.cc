// fluxcal: command-line entry point. Subcommands register themselves (see
// cli/command.h); this file only dispatches.
#include <cstdio>
#include <string>
#include <vector>

#include "cli/command.h"

namespace fluxcal::cli {
std::map<std::string, Command>& CommandRegistry() {
  static std::map<std::string, Command> registry;
  return registry;
}
}  // namespace fluxcal::cli

namespace {
void PrintUsage() {
  std::fprintf(stderr, "usage: fluxcal <command> [args]\n\ncommands:\n");
  for (const auto& [name, cmd] : fluxcal::cli::CommandRegistry()) {
    std::fprintf(stderr, "  %-10s %s\n", name.c_str(), cmd.summary.c_str());
  }
}
}  // namespace

int main(int argc, char** argv) {
  if (argc < 2 || std::string(argv[1]) == "help" || std::string(argv[1]) == "--help" ||
      std::string(argv[1]) == "-h") {
    PrintUsage();
    return argc < 2 ? 2 : 0;
  }
  auto& reg = fluxcal::cli::CommandRegistry();
  auto it = reg.find(argv[1]);
  if (it == reg.end()) {
    std::fprintf(stderr, "fluxcal: unknown command '%s'\n", argv[1]);
    PrintUsage();
    return 2;
  }
  std::vector<std::string> args(argv + 2, argv + argc);
  return it->second.run(args);
}
