#include "cli/support_output.h"

#include <cstdio>
#include <iostream>

namespace fluxcal::cli {

void PrintJson(const nlohmann::json& doc) {
  std::cout << doc.dump(2, ' ', false, nlohmann::json::error_handler_t::replace) << "\n";
}

int CommandError(const std::string& command, const std::string& message, int code) {
  std::fprintf(stderr, "fluxcal %s: %s\n", command.c_str(), message.c_str());
  return code;
}

}  // namespace fluxcal::cli
