// What every command prints the same way (docs/cli.md, "Output"): the one
// JSON document of --json on stdout, a refusal on stderr.
#ifndef FLUXCAL_CLI_SUPPORT_OUTPUT_H_
#define FLUXCAL_CLI_SUPPORT_OUTPUT_H_

#include <string>

#include "nlohmann/json.hpp"

namespace fluxcal::cli {

// doc on stdout, indented by two, bytes that are not UTF-8 replaced.
void PrintJson(const nlohmann::json& doc);

// "fluxcal COMMAND: MESSAGE" on stderr; returns code (the exit status).
int CommandError(const std::string& command, const std::string& message, int code = 1);

}  // namespace fluxcal::cli

#endif  // FLUXCAL_CLI_SUPPORT_OUTPUT_H_
