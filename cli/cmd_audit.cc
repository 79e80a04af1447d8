// fluxcal audit SERIAL --server ADDR [--json]
// The serial's audit trail: every write the service took (ingest, fit,
// release) with the authenticated identity and role, the peer address, the
// time and the request id. Needs the engineer, release or admin role.
#include <cstdio>

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "cli/support_remote.h"

namespace fluxcal::cli {
namespace {

constexpr char kAuditUsage[] = "fluxcal audit SERIAL --server ADDR [--json]";
const FlagSpecs kAuditFlags = {kServerFlag, kJsonFlag};

int PrintAudit(const v1::AuditResponse& resp, bool json) {
  if (json) {
    nlohmann::json arr = nlohmann::json::array();
    for (const auto& e : resp.entries()) {
      arr.push_back({{"id", e.id()}, {"utc", e.utc()}, {"identity", e.identity()}, {"role", e.role()},
                     {"peer", e.peer()}, {"request_id", e.request_id()}, {"rpc", e.rpc()}, {"detail", e.detail()}});
    }
    PrintJson({{"serial", resp.serial()}, {"entries", arr}});
    return 0;
  }
  for (const auto& e : resp.entries()) {
    std::printf("%s  %-16s %-9s %-15s %-24s %s  (request %s)\n", e.utc().c_str(), e.identity().c_str(),
                e.role().c_str(), e.rpc().c_str(), e.peer().c_str(), e.detail().c_str(), e.request_id().c_str());
  }
  return 0;
}

int RunAudit(const std::vector<std::string>& argv) {
  return RunSerialCall("audit", kAuditUsage, argv, kAuditFlags, &v1::CalibrationService::Stub::Audit, PrintAudit);
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("audit", "a serial's audit trail: who wrote what, from where, when", RunAudit, kAuditUsage,
                         kAuditFlags);

}  // namespace fluxcal::cli
