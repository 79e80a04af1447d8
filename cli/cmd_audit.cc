// fluxcal audit SERIAL --server ADDR [--json]
// The serial's audit trail: every write the service took (ingest, fit,
// release) with the authenticated identity and role, the peer address, the
// time and the request id. Needs the engineer, release or admin role.
#include <cstdio>
#include <iostream>

#include <grpcpp/grpcpp.h>

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_remote.h"
#include "nlohmann/json.hpp"

namespace fluxcal::cli {
namespace {

const FlagSpecs kAuditFlags = {
    {"server", "ADDR", "the service, HOST[:PORT] (default port 50051; required)"},
    {"json", "", "print the result as one JSON document"},
};

int RunAudit(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kAuditFlags);
  if (!args.ok() || args->positional.size() != 1 || !args->Get("server")) {
    std::fprintf(stderr, "usage: fluxcal audit SERIAL --server ADDR [--json]\n");
    return 2;
  }
  auto stub = MakeStub(*args->Get("server"));
  if (!stub) return 1;
  v1::AuditRequest req;
  req.set_serial(args->positional[0]);
  v1::AuditResponse resp;
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(30));
  auto s = stub->Audit(&ctx, req, &resp);
  if (!s.ok()) return ReportRpcError("audit", s);
  if (args->Has("json")) {
    nlohmann::json arr = nlohmann::json::array();
    for (const auto& e : resp.entries()) {
      arr.push_back({{"id", e.id()}, {"utc", e.utc()}, {"identity", e.identity()}, {"role", e.role()},
                     {"peer", e.peer()}, {"request_id", e.request_id()}, {"rpc", e.rpc()}, {"detail", e.detail()}});
    }
    std::cout << nlohmann::json{{"serial", resp.serial()}, {"entries", arr}}
                     .dump(2, ' ', false, nlohmann::json::error_handler_t::replace)
              << "\n";
    return 0;
  }
  for (const auto& e : resp.entries()) {
    std::printf("%s  %-16s %-9s %-15s %-24s %s  (request %s)\n", e.utc().c_str(), e.identity().c_str(),
                e.role().c_str(), e.rpc().c_str(), e.peer().c_str(), e.detail().c_str(), e.request_id().c_str());
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("audit", "a serial's audit trail: who wrote what, from where, when", RunAudit,
                         "fluxcal audit SERIAL --server ADDR [--json]",
                         kAuditFlags);

}  // namespace fluxcal::cli
