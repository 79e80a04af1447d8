// The store of the admin commands that only read it (--db URL).
#ifndef FLUXCAL_CLI_SUPPORT_STORE_H_
#define FLUXCAL_CLI_SUPPORT_STORE_H_

#include <memory>
#include <string>
#include <vector>

#include "cli/args.h"
#include "pipeline/store.h"

namespace fluxcal::cli {

// The store --db names, opened without creating it (a store that does not
// exist is refused, never created); nullptr after "fluxcal COMMAND: flag
// --db: why" on stderr.
std::unique_ptr<storage::Store> OpenExistingStore(const std::string& command, const ParsedArgs& args);

// `fluxcal COMMAND --db URL [flags]` of a command that only reads the store:
// argv parsed by flags (no positional argument, --db required) into *args
// and the store opened into *store. 0, or the exit status after the reason
// on stderr: 2 with the parse error and the usage, 1 without a store.
int ParseArgsAndOpenStore(const std::string& command, const std::vector<std::string>& argv, const FlagSpecs& flags,
                          const std::string& usage, ParsedArgs* args, std::unique_ptr<storage::Store>* store);

}  // namespace fluxcal::cli

#endif  // FLUXCAL_CLI_SUPPORT_STORE_H_
