// The store of the admin commands that only read it (--db URL).
#ifndef FLUXCAL_CLI_SUPPORT_STORE_H_
#define FLUXCAL_CLI_SUPPORT_STORE_H_

#include <memory>
#include <string>

#include "cli/args.h"
#include "pipeline/store.h"

namespace fluxcal::cli {

// The store --db names, opened without creating it (a store that does not
// exist is refused, never created); nullptr after "fluxcal COMMAND: flag
// --db: why" on stderr.
std::unique_ptr<storage::Store> OpenExistingStore(const std::string& command, const ParsedArgs& args);

}  // namespace fluxcal::cli

#endif  // FLUXCAL_CLI_SUPPORT_STORE_H_
