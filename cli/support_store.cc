#include "cli/support_store.h"

#include "cli/support_output.h"

namespace fluxcal::cli {

std::unique_ptr<storage::Store> OpenExistingStore(const std::string& command, const ParsedArgs& args) {
  auto store = pipeline::OpenStore(args.Get("db").value_or(""), /*create=*/false);
  if (!store.ok()) {
    CommandError(command, "flag --db: " + std::string(store.status().message()));
    return nullptr;
  }
  return std::move(*store);
}

int ParseArgsAndOpenStore(const std::string& command, const std::vector<std::string>& argv, const FlagSpecs& flags,
                          const std::string& usage, ParsedArgs* args, std::unique_ptr<storage::Store>* store) {
  auto parsed = ParseArgs(argv, flags);
  if (!parsed.ok() || !parsed->Get("db") || !parsed->positional.empty()) {
    if (!parsed.ok()) CommandError(command, std::string(parsed.status().message()));
    return UsageError(usage);
  }
  *args = std::move(*parsed);
  *store = OpenExistingStore(command, *args);
  return *store ? 0 : 1;
}

}  // namespace fluxcal::cli
