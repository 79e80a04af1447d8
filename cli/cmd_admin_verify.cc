// fluxcal admin verify-db --db PATH|postgresql://... [--json]
// Recomputes the hash chain over every stored calibration version
// (storage::VerifyCalibrationChain): a row changed, removed or inserted
// around the service (e.g. by editing the SQLite file with its triggers
// dropped) is reported with serial and version. Exit 0 intact, 1 not.
#include <cstdio>
#include <iostream>

#include "cli/args.h"
#include "cli/command.h"
#include "nlohmann/json.hpp"
#include "storage/store.h"

namespace fluxcal::cli {
namespace {

const FlagSpecs kVerifyDbFlags = {
    {"db", "URL", "the store: SQLite PATH or postgresql://... (required)"},
    {"json", "", "print the result as one JSON document"},
};

int RunVerifyDb(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kVerifyDbFlags);
  if (!args.ok() || !args->Get("db") || !args->positional.empty()) {
    std::fprintf(stderr, "usage: fluxcal admin verify-db --db PATH|postgresql://... [--json]\n");
    return 2;
  }
  auto store = storage::Store::Open(*args->Get("db"));
  if (!store.ok()) {
    std::fprintf(stderr, "fluxcal admin verify-db: %s\n", std::string(store.status().message()).c_str());
    return 1;
  }
  auto rep = storage::VerifyCalibrationChain(**store);
  if (!rep.ok()) {
    std::fprintf(stderr, "fluxcal admin verify-db: %s\n", std::string(rep.status().message()).c_str());
    return 1;
  }
  const bool intact = rep->problems.empty();
  if (args->Has("json")) {
    std::cout << nlohmann::json{{"intact", intact}, {"chained", rep->chained}, {"unchained", rep->unchained},
                                {"problems", rep->problems}}
                     .dump(2, ' ', false, nlohmann::json::error_handler_t::replace)
              << "\n";
  } else {
    std::printf("%s: %d calibration versions chained, %d from before the chain%s\n", intact ? "intact" : "TAMPERED",
                rep->chained, rep->unchained, intact ? "" : ":");
    for (const auto& p : rep->problems) std::printf("  %s\n", p.c_str());
  }
  return intact ? 0 : 1;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("admin verify-db", "check the hash chain over stored calibrations (tampering)", RunVerifyDb,
                         "fluxcal admin verify-db --db PATH|postgresql://... [--json]",
                         kVerifyDbFlags);

}  // namespace fluxcal::cli
