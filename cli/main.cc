// fluxcal: command-line entry point. Subcommands register themselves (see
// cli/command.h); this file only dispatches.
#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "cli/args.h"
#include "cli/build_info.h"   // generated: cmake/build_info.cmake
#include "cli/command.h"
#include "cli/support_remote.h"
#include "nlohmann/json.hpp"

namespace fluxcal::cli {
std::map<std::string, Command>& CommandRegistry() {
  static std::map<std::string, Command> registry;
  return registry;
}
}  // namespace fluxcal::cli

namespace {
using fluxcal::cli::Command;
using fluxcal::cli::FlagSpecs;

// The client flags every command with --server takes (cli/support_remote.h).
const FlagSpecs& ClientFlags() {
  static const FlagSpecs flags = {
      {"ca", "PEM", "trust these CA roots (TLS; default the system's; env FLUXCAL_CA)"},
      {"cert", "PEM", "client certificate for mutual TLS (env FLUXCAL_CERT)"},
      {"key", "PEM", "private key of --cert (env FLUXCAL_KEY)"},
      {"token-file", "FILE", "send its first line as bearer token (env FLUXCAL_TOKEN_FILE)"},
      {"insecure", "", "plaintext even off loopback (loopback is plaintext unless --ca)"},
  };
  return flags;
}

void PrintUsage(FILE* to) {
  std::fprintf(to, "usage: fluxcal <command> [args]   (fluxcal help COMMAND, or COMMAND --help, for its flags)\n"
                   "       fluxcal --version [--json]   (release, git commit, build type)\n\ncommands:\n");
  for (const auto& [name, cmd] : fluxcal::cli::CommandRegistry()) {
    std::fprintf(to, "  %-16s %s\n", name.c_str(), cmd.summary.c_str());
  }
}

void PrintFlags(const FlagSpecs& flags) {
  for (const auto& f : flags) {
    std::string left = "--" + f.name + (f.value.empty() ? "" : " " + f.value);
    if (left.size() > 24) {
      std::printf("  %s\n  %-24s %s\n", left.c_str(), "", f.help.c_str());
    } else {
      std::printf("  %-24s %s\n", left.c_str(), f.help.c_str());
    }
  }
}

// `fluxcal COMMAND --help` and `fluxcal help COMMAND`: on stdout, rc 0.
void PrintCommandHelp(const Command& cmd) {
  std::string usage = cmd.usage.empty() ? "fluxcal " + cmd.name + " [flags]" : cmd.usage;
  std::printf("usage: ");
  for (size_t pos = 0; pos <= usage.size();) {
    const size_t nl = std::min(usage.find('\n', pos), usage.size());
    std::printf("%s%s\n", pos == 0 ? "" : "       ", usage.substr(pos, nl - pos).c_str());
    pos = nl + 1;
  }
  std::printf("\n%s\n\nflags:\n", cmd.summary.c_str());
  PrintFlags(cmd.flags);
  std::printf("  %-24s %s\n", "-h, --help", "this help");
  if (cmd.server_client) {
    std::printf("\nclient flags (with --server; HOST alone means port %d):\n", fluxcal::cli::kDefaultPort);
    PrintFlags(ClientFlags());
  }
  std::printf("\nexit status: 0 ok, 1 bad input or failure, 2 usage error%s\n", cmd.name == "eol" ? ", 3 verdict fail" : "");
}

// Finds the command named by argv[first..]: two words first, then one.
std::map<std::string, Command>::iterator FindCommand(int argc, char** argv, int first, int* words) {
  auto& reg = fluxcal::cli::CommandRegistry();
  auto it = reg.end();
  *words = 1;
  if (argc > first + 1) it = reg.find(std::string(argv[first]) + " " + argv[first + 1]);
  if (it != reg.end()) {
    *words = 2;
    return it;
  }
  return reg.find(argv[first]);
}

// The commands "GROUP ..." of a two-word group ("map"); false if none.
bool PrintGroup(FILE* to, const std::string& group) {
  bool any = false;
  for (const auto& [name, cmd] : fluxcal::cli::CommandRegistry()) {
    if (name.rfind(group + " ", 0) == 0) {
      if (!any) std::fprintf(to, "fluxcal %s commands (fluxcal help COMMAND for each):\n", group.c_str());
      std::fprintf(to, "  %-16s %s\n", name.c_str(), cmd.summary.c_str());
      any = true;
    }
  }
  return any;
}

// `fluxcal help --json`: the registry (names, usage, flags) as one document.
void PrintRegistryJson() {
  nlohmann::json doc = nlohmann::json::array();
  for (const auto& [name, cmd] : fluxcal::cli::CommandRegistry()) {
    nlohmann::json flags = nlohmann::json::array();
    for (const auto& f : cmd.flags) flags.push_back({{"name", f.name}, {"value", f.value}, {"help", f.help}});
    doc.push_back({{"name", name}, {"summary", cmd.summary}, {"usage", cmd.usage}, {"flags", flags},
                   {"server_client", cmd.server_client}});
  }
  std::printf("%s\n", doc.dump(2).c_str());
}
}  // namespace

int main(int argc, char** argv) {
  if (argc >= 2 && (std::string(argv[1]) == "--version" || std::string(argv[1]) == "version")) {
    // The release, the commit the binary was built from and the build type
    // (cmake/build_info.cmake): enough to tell two builds apart in a report.
    const bool json = argc == 3 && std::string(argv[2]) == "--json";
    if (argc > 2 && !json) {
      std::fprintf(stderr, "usage: fluxcal --version [--json]\n");
      return 2;
    }
    if (json) {
      std::printf("%s\n", nlohmann::json{{"version", FLUXCAL_VERSION},
                                         {"commit", FLUXCAL_GIT_DESCRIBE},
                                         {"build_type", FLUXCAL_BUILD_TYPE}}.dump(2).c_str());
    } else {
      std::printf("fluxcal %s (commit %s, %s build)\n", FLUXCAL_VERSION, FLUXCAL_GIT_DESCRIBE, FLUXCAL_BUILD_TYPE);
    }
    return 0;
  }
  if (argc < 2) {
    PrintUsage(stderr);
    return 2;
  }
  auto& reg = fluxcal::cli::CommandRegistry();
  if (std::string(argv[1]) == "help" || std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h") {
    if (argc == 2) {
      PrintUsage(stdout);
      return 0;
    }
    if (argc == 3 && std::string(argv[2]) == "--json") {
      PrintRegistryJson();
      return 0;
    }
    int words = 1;
    auto it = FindCommand(argc, argv, 2, &words);
    if (it == reg.end() && argc == 3 && PrintGroup(stdout, argv[2])) return 0;
    if (it == reg.end() || 2 + words != argc) {
      std::fprintf(stderr, "fluxcal help: unknown command '%s'\n", argv[2]);
      PrintUsage(stderr);
      return 2;
    }
    PrintCommandHelp(it->second);
    return 0;
  }
  // Two-word commands ("admin add-key") first, then one word.
  int words = 1;
  auto it = FindCommand(argc, argv, 1, &words);
  if (it == reg.end()) {
    // A group alone ("fluxcal map --help"): its commands.
    if (argc == 3 && (std::string(argv[2]) == "--help" || std::string(argv[2]) == "-h") &&
        PrintGroup(stdout, argv[1])) {
      return 0;
    }
    std::fprintf(stderr, "fluxcal: unknown command '%s'\n", argv[1]);
    PrintUsage(stderr);
    return 2;
  }
  std::vector<std::string> args(argv + 1 + words, argv + argc);
  {
    FlagSpecs all = it->second.flags;
    if (it->second.server_client) all.insert(all.end(), ClientFlags().begin(), ClientFlags().end());
    if (fluxcal::cli::WantsHelp(args, all)) {
      PrintCommandHelp(it->second);
      return 0;
    }
  }
  // The client flags (--ca, --cert, --key, --token-file, --insecure) mean
  // the same for every command that talks to a server; `serve` has its own.
  if (it->first != "serve") {
    if (std::string err = fluxcal::cli::TakeClientFlags(&args); !err.empty()) {
      std::fprintf(stderr, "fluxcal %s: %s\n", it->first.c_str(), err.c_str());
      return 2;
    }
  }
  // Every flag checked against the command's declaration before it runs:
  // a typo fails in milliseconds, not after the work.
  if (!it->second.flags.empty()) {
    if (auto parsed = fluxcal::cli::ParseArgs(args, it->second.flags); !parsed.ok()) {
      std::fprintf(stderr, "fluxcal %s: %s (fluxcal %s --help lists the flags)\n", it->first.c_str(),
                   std::string(parsed.status().message()).c_str(), it->first.c_str());
      return 2;
    }
  }
  return it->second.run(args);
}
