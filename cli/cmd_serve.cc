// fluxcal serve --db PATH|sqlite:PATH|postgresql://... --listen 127.0.0.1:50051
//   [--tls-cert PEM --tls-key PEM [--client-ca PEM [--require-client-cert]]]
//   [--auth KEYS] [--signing-key ED25519.key] [--anchor-file FILE] [--insecure] [--quiet]
// Runs the calibration service until SIGINT/SIGTERM. A path is a SQLite
// file (the embedded default); a postgresql:// URI makes the server
// stateless, so several may share one database behind a load balancer.
//
// Transport and identity (docs/security.md): off loopback the service needs
// TLS (or an explicit --insecure) and a keys file (--auth): deny by
// default. On loopback without --auth it runs open, for a bench PC or
// development, and says so.
#include <csignal>
#include <cstdio>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "cli/args.h"
#include "cli/command.h"
#include "io/csv.h"
#include "server/auth.h"
#include "server/service.h"
#include "storage/store.h"
#include "tables/signature.h"

namespace fluxcal::cli {
namespace {

volatile std::sig_atomic_t g_stop = 0;
void OnSignal(int) { g_stop = 1; }

constexpr char kUsage[] =
    "usage: fluxcal serve --db PATH|postgresql://USER@HOST:PORT/DB --listen HOST:PORT\n"
    "                     [--tls-cert PEM --tls-key PEM [--client-ca PEM]]\n"
    "                     [--require-client-cert] [--auth KEYS.json] [--signing-key ED25519.key] [--insecure]\n"
    "                     [--anchor-file FILE] [--quiet]\n";

const FlagSpecs kServeFlags = {
    {"db", "URL", "the store (required): a SQLite file PATH or sqlite:PATH, or postgresql://USER@HOST:PORT/DB"},
    {"listen", "HOST:PORT", "address to listen on (default 127.0.0.1:50051; port 0: any free port)"},
    {"tls-cert", "PEM", "server certificate chain (TLS; with --tls-key)"},
    {"tls-key", "PEM", "private key of --tls-cert"},
    {"client-ca", "PEM", "CA of accepted client certificates (mutual TLS; needs --tls-cert)"},
    {"require-client-cert", "", "refuse clients without a certificate signed by --client-ca"},
    {"auth", "KEYS.json", "identities and roles (fluxcal admin add-key); required off loopback"},
    {"signing-key", "ED25519.key", "sign exported tables (Ed25519 private key PEM)"},
    {"anchor-file", "FILE", "append the chain heads after every fit and release (fluxcal admin verify-db --anchor)"},
    {"insecure", "", "plaintext off loopback (test networks only)"},
    {"quiet", "", "no per-request log lines on stderr"},
};

int RunServe(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kServeFlags);
  if (!args.ok() || !args->positional.empty()) {
    if (!args.ok()) std::fprintf(stderr, "fluxcal serve: %s\n", std::string(args.status().message()).c_str());
    std::fprintf(stderr, "%s", kUsage);
    return 2;
  }
  if (!args->Get("db")) {
    // No silent ./fluxcal.db: a service writes where it is told.
    std::fprintf(stderr, "fluxcal serve: --db is required (a SQLite file PATH or postgresql://...)\n%s", kUsage);
    return 2;
  }
  const std::string db = *args->Get("db");
  const std::string listen = args->Get("listen").value_or("127.0.0.1:50051");
  server::ServerOptions opt;
  auto pem = [&](const char* flag, std::string* out) {
    if (auto path = args->Get(flag)) {
      auto text = io::ReadFileToString(*path);
      if (!text.ok()) {
        std::fprintf(stderr, "fluxcal serve: --%s %s: cannot read\n", flag, path->c_str());
        return false;
      }
      *out = std::move(*text);
    }
    return true;
  };
  if (!pem("tls-cert", &opt.tls_cert_pem) || !pem("tls-key", &opt.tls_key_pem) ||
      !pem("client-ca", &opt.client_ca_pem)) {
    return 2;
  }
  if (opt.tls_cert_pem.empty() != opt.tls_key_pem.empty()) {
    std::fprintf(stderr, "fluxcal serve: --tls-cert and --tls-key go together\n");
    return 2;
  }
  if (!opt.client_ca_pem.empty() && opt.tls_cert_pem.empty()) {
    std::fprintf(stderr, "fluxcal serve: --client-ca needs --tls-cert and --tls-key\n");
    return 2;
  }
  opt.require_client_cert = args->Has("require-client-cert");
  if (opt.require_client_cert && opt.client_ca_pem.empty()) {
    std::fprintf(stderr, "fluxcal serve: --require-client-cert needs --client-ca\n");
    return 2;
  }
  const bool loopback = server::IsLoopbackAddress(listen);
  const bool tls = !opt.tls_cert_pem.empty();
  if (!loopback && !tls && !args->Has("insecure")) {
    std::fprintf(stderr,
                 "fluxcal serve: %s is not a loopback address: give --tls-cert and --tls-key (or --insecure to "
                 "serve plaintext on purpose)\n",
                 listen.c_str());
    return 2;
  }
  std::unique_ptr<server::Authorizer> auth;
  if (auto keys_path = args->Get("auth")) {
    auto keys = server::LoadKeys(*keys_path);
    if (!keys.ok()) {
      std::fprintf(stderr, "fluxcal serve: %s\n", std::string(keys.status().message()).c_str());
      return 1;
    }
    auth = std::make_unique<server::Authorizer>(std::move(*keys));
  } else if (!loopback) {
    std::fprintf(stderr,
                 "fluxcal serve: %s is not a loopback address: give --auth KEYS.json (fluxcal admin add-key); "
                 "the service denies by default\n",
                 listen.c_str());
    return 2;
  }
  auto store = storage::Store::Open(db);
  if (!store.ok()) {
    std::fprintf(stderr, "fluxcal serve: %s\n", std::string(store.status().message()).c_str());
    return 1;
  }
  server::CalibrationServiceImpl service(store->get());
  service.set_authorizer(auth.get());
  if (auto anchor = args->Get("anchor-file")) service.set_anchor_file(*anchor);
  std::string signing_key;
  if (!pem("signing-key", &signing_key)) return 2;
  if (!signing_key.empty()) {
    if (auto pub = tables::PublicPemOf(signing_key); !pub.ok()) {
      std::fprintf(stderr, "fluxcal serve: --signing-key: %s\n", std::string(pub.status().message()).c_str());
      return 2;
    }
    service.set_signing_key(signing_key);
  }
  opt.authorizer = auth.get();
  opt.log_requests = !args->Has("quiet");
  // Reflection (v1 and v1alpha) describes the API only; with identities on
  // it answers authenticated callers of any role, so nothing but health
  // answers an anonymous one (server/reflection.h).
  opt.reflection = true;
  int port = 0;
  auto srv = server::StartServer(&service, listen, &port, opt);
  if (!srv || port == 0) {
    std::fprintf(stderr, "fluxcal serve: cannot listen on %s\n", listen.c_str());
    return 1;
  }
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  // Never print a password from the URI.
  const std::string shown = (*store)->Backend() == "postgresql" ? "postgresql" : db;
  std::fprintf(stderr, "fluxcal serve: listening on %s (port %d, %s%s), store %s\n", listen.c_str(), port,
               tls ? "TLS" : "plaintext", tls && !opt.client_ca_pem.empty() ? " with client certificates" : "",
               shown.c_str());
  if (!auth) std::fprintf(stderr, "fluxcal serve: no --auth: open on loopback, every caller is admin\n");
  std::fflush(stderr);
  std::thread waiter([&] { srv->Wait(); });
  while (!g_stop) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  std::fprintf(stderr, "fluxcal serve: shutting down\n");
  srv->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(5));
  waiter.join();
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("serve", "run the gRPC calibration service (SQLite file or PostgreSQL)", RunServe,
                         "fluxcal serve --db PATH|postgresql://USER@HOST:PORT/DB [--listen HOST:PORT]\n"
                         "  [--tls-cert PEM --tls-key PEM [--client-ca PEM [--require-client-cert]]]\n"
                         "  [--auth KEYS.json] [--signing-key ED25519.key] [--anchor-file FILE] [--insecure] [--quiet]",
                         kServeFlags);

}  // namespace fluxcal::cli
