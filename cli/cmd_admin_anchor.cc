// fluxcal admin anchor --db PATH|postgresql://... [--out FILE] [--json]
// The head of both hash chains (every serial's newest chained version and
// its hash, the newest release link, one digest over all of it); with --out
// appended to FILE as one line (pipeline/anchor.h). Keep FILE outside the
// database's host: `fluxcal admin verify-db --anchor FILE` then names a
// newest version or release removed after it (docs/security.md). Only
// reads: a store that does not exist is refused, never created.
#include <cstdio>
#include <iostream>

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_store.h"
#include "pipeline/anchor.h"

namespace fluxcal::cli {
namespace {

constexpr char kAnchorUsage[] = "fluxcal admin anchor --db PATH|postgresql://... [--out FILE] [--json]";
const FlagSpecs kAnchorFlags = {
    kExistingDbFlag,
    {"out", "FILE", "append the anchor line to FILE (created if missing)"},
    JsonFlag("the anchor"),
};

int RunAnchor(const std::vector<std::string>& argv) {
  ParsedArgs args;
  std::unique_ptr<storage::Store> store;
  if (int rc = ParseArgsAndOpenStore("admin anchor", argv, kAnchorFlags, kAnchorUsage, &args, &store); rc != 0) {
    return rc;
  }
  const std::string out = args.Get("out").value_or("");
  auto head = pipeline::AnchorStore(*store, out);
  if (!head.ok()) return CommandError("admin anchor", (out.empty() ? "" : "flag --out: ") + std::string(head.status().message()));
  if (args.Has("json")) {
    std::cout << pipeline::AnchorLine(*head, "snapshot", store->Backend(), pipeline::StoreNowUtc()) << "\n";
  } else {
    std::printf("anchor %s: %zu serials", head->digest_sha256.c_str(), head->calibrations.size());
    if (head->release_seq > 0) {
      std::printf(", newest release #%lld (%s v%d)", static_cast<long long>(head->release_seq),
                  head->release_serial.c_str(), head->release_version);
    }
    std::printf("%s\n", out.empty() ? "" : (", appended to " + out).c_str());
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("admin anchor", "print or append the chain heads to keep outside the database", RunAnchor,
                         kAnchorUsage, kAnchorFlags);

}  // namespace fluxcal::cli
