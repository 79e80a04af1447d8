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

}  // namespace fluxcal::cli
