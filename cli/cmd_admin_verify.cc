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

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_store.h"
#include "nlohmann/json.hpp"
#include "pipeline/anchor.h"

namespace fluxcal::cli {
namespace {

constexpr char kVerifyDbUsage[] = "fluxcal admin verify-db --db PATH|postgresql://... [--anchor FILE] [--json]";
const FlagSpecs kVerifyDbFlags = {
    kExistingDbFlag,
    {"anchor", "FILE", "chain heads kept outside the database (fluxcal admin anchor --out, serve --anchor-file)"},
    kJsonFlag,
};

int RunVerifyDb(const std::vector<std::string>& argv) {
  ParsedArgs args;
  std::unique_ptr<storage::Store> store;
  if (int rc = ParseArgsAndOpenStore("admin verify-db", argv, kVerifyDbFlags, kVerifyDbUsage, &args, &store);
      rc != 0) {
    return rc;
  }
  const std::string anchor = args.Get("anchor").value_or("");
  auto rep = pipeline::VerifyStore(*store, anchor);
  if (!rep.ok()) {
    return CommandError("admin verify-db", (anchor.empty() ? "" : "flag --anchor: ") + std::string(rep.status().message()));
  }
  const bool intact = rep->problems.empty();
  if (args.Has("json")) {
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
    PrintJson(j);
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
                         RunVerifyDb, kVerifyDbUsage, kVerifyDbFlags);

}  // namespace fluxcal::cli
