// Client side of the calibration service for the CLI subcommands that take
// --server ADDR.
#ifndef FLUXCAL_CLI_SUPPORT_REMOTE_H_
#define FLUXCAL_CLI_SUPPORT_REMOTE_H_

#include <memory>
#include <string>
#include <vector>

#include "fluxcal/v1/calibration.grpc.pb.h"

namespace fluxcal::cli {

std::unique_ptr<v1::CalibrationService::Stub> MakeStub(const std::string& address);
// Prints "fluxcal <cmd>: <code>: <message>" to stderr and returns the exit code.
int ReportRpcError(const char* cmd, const grpc::Status& s);

int RunRemoteQuery(const std::vector<std::string>& argv);
int RunRemoteExport(const std::vector<std::string>& argv);

}  // namespace fluxcal::cli

#endif  // FLUXCAL_CLI_SUPPORT_REMOTE_H_
