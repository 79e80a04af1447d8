// fluxcal admin verify-db --db PATH|postgresql://... [--anchor FILE] [--json]
// Recomputes the hash chains over every stored calibration version and
// every release (pipeline::VerifyStore, storage::VerifyChains): a row
// changed, removed or inserted around the service (e.g. by editing the
// SQLite file with its triggers dropped) is reported with serial and
// version. With --anchor (a file `fluxcal admin anchor --out` or `fluxcal
// serve --anchor-file` wrote), a newest version or release removed after
// the anchor together with its chain link is named too. Only reads: a
// store that does not exist is refused, never created. Exit 0 intact, 1
// not (or no store).
#include <cstdio>
#include <iostream>

#include "cli/args.h"
#include "cli/command.h"
#include "nlohmann/json.hpp"
#include "pipeline/anchor.h"
#include "pipeline/store.h"

namespace fluxcal::cli {
namespace {

const FlagSpecs kVerifyDbFlags = {
    {"db", "URL", "the store: SQLite PATH or postgresql://... (required; must exist)"},
    {"anchor", "FILE", "chain heads kept outside the database (fluxcal admin anchor --out, serve --anchor-file)"},
    {"json", "", "print the result as one JSON document"},
};

int RunVerifyDb(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kVerifyDbFlags);
  if (!args.ok() || !args->Get("db") || !args->positional.empty()) {
    if (!args.ok()) std::fprintf(stderr, "fluxcal admin verify-db: %s\n", std::string(args.status().message()).c_str());
    std::fprintf(stderr, "usage: fluxcal admin verify-db --db PATH|postgresql://... [--anchor FILE] [--json]\n");
    return 2;
  }
  auto store = pipeline::OpenStore(*args->Get("db"), /*create=*/false);
  if (!store.ok()) {
    std::fprintf(stderr, "fluxcal admin verify-db: flag --db: %s\n", std::string(store.status().message()).c_str());
    return 1;
  }
  const std::string anchor = args->Get("anchor").value_or("");
  auto rep = pipeline::VerifyStore(**store, anchor);
  if (!rep.ok()) {
    std::fprintf(stderr, "fluxcal admin verify-db: %s%s\n", anchor.empty() ? "" : "flag --anchor: ",
                 std::string(rep.status().message()).c_str());
    return 1;
  }
  const bool intact = rep->problems.empty();
  if (args->Has("json")) {
    nlohmann::json j = {{"intact", intact},
                        {"chained", rep->chained},
                        {"unchained", rep->unchained},
                        {"converted", rep->converted},
                        {"releases_chained", rep->releases_chained},
                        {"problems", rep->problems}};
    if (!anchor.empty()) {
      j["anchor"] = anchor;
      j["anchored"] = rep->anchored;
    }
    std::cout << j.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
  } else {
    std::printf("%s: %d calibration versions chained, %d from before the chain, %d releases chained", intact ? "intact" : "TAMPERED",
                rep->chained, rep->unchained, rep->releases_chained);
    // Versions the v8 migration converted to binary (docs/security.md).
    if (rep->converted > 0) std::printf(" (%d versions checked through their v8 conversion record)", rep->converted);
    if (!anchor.empty()) std::printf(", %d anchored heads unchanged", rep->anchored);
    std::printf("%s\n", intact ? "" : ":");
    for (const auto& p : rep->problems) std::printf("  %s\n", p.c_str());
  }
  return intact ? 0 : 1;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("admin verify-db", "check the hash chains over calibrations and releases (tampering)",
                         RunVerifyDb, "fluxcal admin verify-db --db PATH|postgresql://... [--anchor FILE] [--json]",
                         kVerifyDbFlags);

}  // namespace fluxcal::cli
