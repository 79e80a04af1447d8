// fluxcal release SERIAL --version N --server ADDR [--json]
// Approves a calibration version for flashing (identity with the release
// role; only a version whose verdict is "pass"). Flashing stations then get
// it as "latest released" from `fluxcal export SERIAL --server ...`.
#include <cstdio>

#include "absl/strings/numbers.h"
#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_remote.h"

namespace fluxcal::cli {
namespace {

constexpr char kReleaseUsage[] = "fluxcal release SERIAL --version N --server ADDR [--json]";
const FlagSpecs kReleaseFlags = {
    kServerFlag,
    {"version", "N", "the calibration version to release (required)"},
    kJsonFlag,
};

int RunRelease(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kReleaseFlags);
  int version = 0;
  if (!args.ok() || args->positional.size() != 1 || !args->Get("server") || !args->Get("version") ||
      !absl::SimpleAtoi(*args->Get("version"), &version) || version <= 0) {
    return UsageError(kReleaseUsage);
  }
  v1::ReleaseRequest req;
  req.set_serial(args->positional[0]);
  req.set_version(version);
  v1::ReleaseResponse resp;
  const std::string server = *args->Get("server");
  if (int rc = CallService("release", server, &v1::CalibrationService::Stub::Release, req, &resp); rc != 0) return rc;
  if (args->Has("json")) {
    PrintJson({{"serial", resp.serial()}, {"version", resp.version()}, {"released_by", resp.released_by()}});
  } else {
    std::printf("%s v%d released for flashing by %s\n", resp.serial().c_str(), resp.version(),
                resp.released_by().c_str());
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("release", "approve a passing calibration version for flashing (release role)", RunRelease,
                         kReleaseUsage, kReleaseFlags);

}  // namespace fluxcal::cli
