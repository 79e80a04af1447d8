// fluxcal serve --db PATH|sqlite:PATH|postgresql://... --listen 127.0.0.1:50051
//   [--tls-cert PEM --tls-key PEM [--client-ca PEM [--require-client-cert]]]
//   [--auth KEYS] [--signing-key ED25519.key] [--anchor-file FILE] [--insecure] [--quiet]
//   [--max-streams-per-identity N] [--max-inflight-bytes-per-identity BYTES]
// Runs the calibration service until SIGINT/SIGTERM; SIGHUP re-reads the
// keys file (so does a change of the file, within a second). A path is a
// SQLite file (the embedded default); a postgresql:// URI makes the server
// stateless, so several may share one database behind a load balancer.
//
// Transport and identity (docs/security.md): off loopback the service needs
// TLS (or an explicit --insecure) and a keys file (--auth): deny by
// default. On loopback without --auth it runs open, for a bench PC or
// development, and says so. Loopback is what the listen address resolves
// to (io/net.h), every address of it, not how it is spelt.
#include <csignal>
#include <cstdio>
#include <thread>
#include <type_traits>

#include "absl/strings/numbers.h"

#include <grpcpp/grpcpp.h>

#include "cli/args.h"
#include "cli/command.h"
#include "io/csv.h"
#include "io/net.h"
#include "pipeline/signing.h"
#include "pipeline/store.h"
#include "server/auth.h"
#include "server/limits.h"
#include "server/service.h"

namespace fluxcal::cli {
namespace {

volatile std::sig_atomic_t g_stop = 0;
volatile std::sig_atomic_t g_reload = 0;
void OnSignal(int) { g_stop = 1; }
void OnHangup(int) { g_reload = 1; }

constexpr char kUsage[] =
    "usage: fluxcal serve --db PATH|postgresql://USER@HOST:PORT/DB --listen HOST:PORT\n"
    "                     [--tls-cert PEM --tls-key PEM [--client-ca PEM]]\n"
    "                     [--require-client-cert] [--auth KEYS.json] [--signing-key ED25519.key] [--insecure]\n"
    "                     [--anchor-file FILE] [--quiet] [--max-streams-per-identity N]\n"
    "                     [--max-inflight-bytes-per-identity BYTES]\n";

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
    {"max-streams-per-identity", "N", "open calls one identity may have at once (default 16)"},
    {"max-inflight-bytes-per-identity", "BYTES",
     "request bytes one identity's open calls may hold (default 536870912, 512 MiB)"},
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
  server::IdentityLimits limits;
  // A positive whole number up to `max` from --flag, or the default kept.
  auto whole = [&](const char* flag, long long max, auto* out) {
    auto v = args->Get(flag);
    if (!v) return true;
    long long n = 0;
    if (!absl::SimpleAtoi(*v, &n) || n < 1 || n > max) {
      std::fprintf(stderr, "fluxcal serve: flag --%s: expected a whole number from 1 to %lld, got '%s'\n", flag, max,
                   io::Printable(*v).c_str());
      return false;
    }
    *out = static_cast<std::remove_pointer_t<decltype(out)>>(n);
    return true;
  };
  if (!whole("max-streams-per-identity", 100000, &limits.max_streams) ||
      !whole("max-inflight-bytes-per-identity", int64_t{1} << 50, &limits.max_inflight_bytes)) {
    return 2;
  }
  // SIGHUP re-reads the keys; it must never end the server, not even
  // while it starts.
  std::signal(SIGHUP, OnHangup);
  const io::LoopbackCheck where = io::CheckLoopback(listen);
  const bool loopback = where.loopback;
  const bool tls = !opt.tls_cert_pem.empty();
  if (!loopback && !tls && !args->Has("insecure")) {
    std::fprintf(stderr,
                 "fluxcal serve: %s is not a loopback address: give --tls-cert and --tls-key (or --insecure to "
                 "serve plaintext on purpose) [%s %s]\n",
                 listen.c_str(), listen.c_str(), where.why.c_str());
    return 2;
  }
  auto log = [](const std::string& m) {
    std::fprintf(stderr, "fluxcal serve: %s\n", m.c_str());
    std::fflush(stderr);
  };
  std::unique_ptr<server::Authorizer> auth;
  if (auto keys_path = args->Get("auth")) {
    auto loaded = server::Authorizer::FromFile(*keys_path, log);
    if (!loaded.ok()) {
      std::fprintf(stderr, "fluxcal serve: %s\n", std::string(loaded.status().message()).c_str());
      return 1;
    }
    auth = std::move(*loaded);
  } else if (!loopback) {
    std::fprintf(stderr,
                 "fluxcal serve: %s is not a loopback address: give --auth KEYS.json (fluxcal admin add-key); "
                 "the service denies by default [%s %s]\n",
                 listen.c_str(), listen.c_str(), where.why.c_str());
    return 2;
  }
  auto store = pipeline::OpenStore(db);
  if (!store.ok()) {
    std::fprintf(stderr, "fluxcal serve: %s\n", std::string(store.status().message()).c_str());
    return 1;
  }
  server::CalibrationServiceImpl service(store->get());
  service.set_authorizer(auth.get());
  if (auto anchor = args->Get("anchor-file")) service.set_anchor_file(*anchor);
  service.set_limits(limits);
  std::string signing_key;
  if (!pem("signing-key", &signing_key)) return 2;
  if (!signing_key.empty()) {
    if (auto st = pipeline::CheckSigningKey(signing_key); !st.ok()) {
      std::fprintf(stderr, "fluxcal serve: --signing-key: %s\n", std::string(st.message()).c_str());
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
  if (!auth) std::fprintf(stderr, "fluxcal serve: no --auth: open on loopback (%s %s), every caller is admin\n", listen.c_str(), where.why.c_str());
  std::fprintf(stderr, "fluxcal serve: per identity at most %d open calls and %lld request bytes in flight\n",
               limits.max_streams, static_cast<long long>(limits.max_inflight_bytes));
  std::fflush(stderr);
  std::thread waiter([&] { srv->Wait(); });
  while (!g_stop) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    if (g_reload) {
      g_reload = 0;
      if (auth) {
        (void)auth->Reload();   // logs the outcome; a broken file keeps the keys before
      } else {
        log("SIGHUP: no --auth keys file to re-read (open mode)");
      }
    }
  }
  std::fprintf(stderr, "fluxcal serve: shutting down\n");
  srv->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(5));
  waiter.join();
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("serve", "run the gRPC calibration service (SQLite file or PostgreSQL)", RunServe,
                         "fluxcal serve --db PATH|postgresql://USER@HOST:PORT/DB [--listen HOST:PORT]\n"
                         "  [--tls-cert PEM --tls-key PEM [--client-ca PEM [--require-client-cert]]]\n"
                         "  [--auth KEYS.json] [--signing-key ED25519.key] [--anchor-file FILE] [--insecure] [--quiet]\n"
                         "  [--max-streams-per-identity N] [--max-inflight-bytes-per-identity BYTES]",
                         kServeFlags);

}  // namespace fluxcal::cli
