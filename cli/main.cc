// fluxcal: command-line entry point. Subcommands register themselves (see
// cli/command.h); this file only dispatches.
#include <cstdio>
#include <string>
#include <vector>

#include "cli/command.h"
#include "cli/support_remote.h"

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
    std::fprintf(stderr, "  %-16s %s\n", name.c_str(), cmd.summary.c_str());
  }
}
}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && (std::string(argv[1]) == "--version" || std::string(argv[1]) == "version")) {
    std::printf("fluxcal %s\n", FLUXCAL_VERSION);
    return 0;
  }
  if (argc < 2 || std::string(argv[1]) == "help" || std::string(argv[1]) == "--help" ||
      std::string(argv[1]) == "-h") {
    PrintUsage();
    return argc < 2 ? 2 : 0;
  }
  auto& reg = fluxcal::cli::CommandRegistry();
  // Two-word commands ("admin add-key") first, then one word.
  int words = 1;
  auto it = reg.end();
  if (argc >= 3) it = reg.find(std::string(argv[1]) + " " + argv[2]);
  if (it != reg.end()) {
    words = 2;
  } else {
    it = reg.find(argv[1]);
  }
  if (it == reg.end()) {
    std::fprintf(stderr, "fluxcal: unknown command '%s'\n", argv[1]);
    PrintUsage();
    return 2;
  }
  std::vector<std::string> args(argv + 1 + words, argv + argc);
  // The client flags (--ca, --cert, --key, --token-file, --insecure) mean
  // the same for every command that talks to a server; `serve` has its own.
  if (it->first != "serve") {
    if (std::string err = fluxcal::cli::TakeClientFlags(&args); !err.empty()) {
      std::fprintf(stderr, "fluxcal %s: %s\n", it->first.c_str(), err.c_str());
      return 2;
    }
  }
  return it->second.run(args);
}
