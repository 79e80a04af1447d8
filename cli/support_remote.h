// Client side of the calibration service for the CLI subcommands that take
// --server ADDR.
#ifndef FLUXCAL_CLI_SUPPORT_REMOTE_H_
#define FLUXCAL_CLI_SUPPORT_REMOTE_H_

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "cli/args.h"
#include "fluxcal/v1/calibration.grpc.pb.h"

namespace fluxcal::cli {

// How clients reach the service. Set once per process from the global
// client flags (cli/main.cc strips them from every command but `serve`):
//   --ca PEM          trust these roots (TLS); else the system's roots
//   --cert PEM --key PEM   client certificate (mutual TLS)
//   --token-file F    send 'authorization: Bearer <first line of F>'
//   --insecure        plaintext even to a non-loopback address (never with a
//                     token: tokens need TLS off loopback)
// The environment gives defaults: FLUXCAL_CA, FLUXCAL_CERT, FLUXCAL_KEY,
// FLUXCAL_TOKEN_FILE. Plaintext is used for loopback addresses unless --ca
// is given; every other address uses TLS unless --insecure. Loopback is
// what the address resolves to (io/net.h), every address of it.
struct ClientOptions {
  std::string ca_file, cert_file, key_file, token_file;
  bool insecure = false;
};
ClientOptions& GlobalClientOptions();
// Removes the client flags above from `args` into GlobalClientOptions();
// returns a usage message on a flag without its value.
std::string TakeClientFlags(std::vector<std::string>* args);

// A stub for `address` (--server: HOST means HOST:50051, see ServerTarget)
// with GlobalClientOptions(). On a bad option (an unreadable file, a token
// that would go in plaintext off loopback) prints the reason and returns
// nullptr.
std::unique_ptr<v1::CalibrationService::Stub> MakeStub(const std::string& address);
// Prints "fluxcal <cmd>: <code>: <message>" to stderr, with a hint for the
// codes a setup mistake gives (server unreachable, TLS, token, role), and
// returns the exit code.
int ReportRpcError(const char* cmd, const grpc::Status& s);

// One unary call on stub with a deadline of `seconds`.
template <class Req, class Resp>
grpc::Status CallWithDeadline(v1::CalibrationService::Stub& stub,
                              grpc::Status (v1::CalibrationService::Stub::*rpc)(grpc::ClientContext*, const Req&,
                                                                                  Resp*),
                              const Req& req, Resp* resp, int seconds = 30) {
  grpc::ClientContext ctx;
  ctx.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(seconds));
  return (stub.*rpc)(&ctx, req, resp);
}

// One unary call to the service at `server` (MakeStub): 0 when it answered,
// else the exit status after the reason on stderr (MakeStub's, or
// ReportRpcError's under the name cmd).
template <class Req, class Resp>
int CallService(const char* cmd, const std::string& server,
                grpc::Status (v1::CalibrationService::Stub::*rpc)(grpc::ClientContext*, const Req&, Resp*),
                const Req& req, Resp* resp, int seconds = 30) {
  auto stub = MakeStub(server);
  if (!stub) return 1;
  if (auto s = CallWithDeadline(*stub, rpc, req, resp, seconds); !s.ok()) return ReportRpcError(cmd, s);
  return 0;
}

// `fluxcal CMD SERIAL --server ADDR [--json]`: argv parsed by flags (the
// usage error otherwise), the one call about SERIAL made, and its answer
// printed by print(resp, json), whose return is the exit status.
template <class Req, class Resp, class Print>
int RunSerialCall(const char* cmd, const std::string& usage, const std::vector<std::string>& argv,
                  const FlagSpecs& flags,
                  grpc::Status (v1::CalibrationService::Stub::*rpc)(grpc::ClientContext*, const Req&, Resp*),
                  Print print) {
  auto args = ParseArgs(argv, flags);
  if (!args.ok() || args->positional.size() != 1 || !args->Get("server")) return UsageError(usage);
  Req req;
  req.set_serial(args->positional[0]);
  Resp resp;
  if (int rc = CallService(cmd, *args->Get("server"), rpc, req, &resp); rc != 0) return rc;
  return print(resp, args->Has("json"));
}

// `query` with --server: its usage error and the second line of its help.
inline constexpr char kRemoteQueryUsage[] =
    "fluxcal query SERIAL --server ADDR --id-a A --iq-a A [--version N] [--json]";

// `query` and `export` with --server; flags: what the mode accepts.
int RunRemoteQuery(const std::vector<std::string>& argv, const FlagSpecs& flags);
int RunRemoteExport(const std::vector<std::string>& argv, const FlagSpecs& flags);

}  // namespace fluxcal::cli

#endif  // FLUXCAL_CLI_SUPPORT_REMOTE_H_
