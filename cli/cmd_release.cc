// fluxcal release SERIAL --version N --server ADDR [--json]
// Approves a calibration version for flashing (identity with the release
// role; only a version whose verdict is "pass"). Flashing stations then get
// it as "latest released" from `fluxcal export SERIAL --server ...`.
#include <cstdio>
#include <iostream>

#include <grpcpp/grpcpp.h>

#include "absl/strings/numbers.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_remote.h"
#include "nlohmann/json.hpp"

namespace fluxcal::cli {
namespace {

const FlagSpecs kReleaseFlags = {
    {"server", "ADDR", "the service, HOST[:PORT] (default port 50051; required)"},
    {"version", "N", "the calibration version to release (required)"},
    {"json", "", "print the result as one JSON document"},
};

int RunRelease(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kReleaseFlags);
  int version = 0;
  if (!args.ok() || args->positional.size() != 1 || !args->Get("server") || !args->Get("version") ||
      !absl::SimpleAtoi(*args->Get("version"), &version) || version <= 0) {
    std::fprintf(stderr, "usage: fluxcal release SERIAL --version N --server ADDR [--json]\n");
    return 2;
  }
  auto stub = MakeStub(*args->Get("server"));
  if (!stub) return 1;
  v1::ReleaseRequest req;
  req.set_serial(args->positional[0]);
  req.set_version(version);
  v1::ReleaseResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto s = stub->Release(&ctx, req, &resp);
  if (!s.ok()) return ReportRpcError("release", s);
  if (args->Has("json")) {
    std::cout << nlohmann::json{{"serial", resp.serial()}, {"version", resp.version()},
                                {"released_by", resp.released_by()}}
                     .dump(2, ' ', false, nlohmann::json::error_handler_t::replace)
              << "\n";
  } else {
    std::printf("%s v%d released for flashing by %s\n", resp.serial().c_str(), resp.version(),
                resp.released_by().c_str());
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("release", "approve a passing calibration version for flashing (release role)", RunRelease,
                         "fluxcal release SERIAL --version N --server ADDR [--json]",
                         kReleaseFlags);

}  // namespace fluxcal::cli
