// fluxcal serve --db PATH|sqlite:PATH|postgresql://... --listen 127.0.0.1:50051
// Runs the calibration service until SIGINT/SIGTERM. A path is a SQLite
// file (the embedded default); a postgresql:// URI makes the server
// stateless, so several may share one database behind a load balancer.
#include <csignal>
#include <cstdio>
#include <thread>

#include <grpcpp/grpcpp.h>

#include "cli/args.h"
#include "cli/command.h"
#include "server/service.h"
#include "storage/store.h"

namespace fluxcal::cli {
namespace {

volatile std::sig_atomic_t g_stop = 0;
void OnSignal(int) { g_stop = 1; }

int RunServe(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, {"db", "listen"}, {});
  if (!args.ok() || !args->positional.empty()) {
    std::fprintf(stderr, "usage: fluxcal serve --db PATH|postgresql://USER@HOST:PORT/DB --listen 127.0.0.1:50051\n");
    return 2;
  }
  const std::string db = args->Get("db").value_or("fluxcal.db");
  const std::string listen = args->Get("listen").value_or("127.0.0.1:50051");
  auto store = storage::Store::Open(db);
  if (!store.ok()) {
    std::fprintf(stderr, "fluxcal serve: %s\n", std::string(store.status().message()).c_str());
    return 1;
  }
  server::CalibrationServiceImpl service(store->get());
  int port = 0;
  auto srv = server::StartServer(&service, listen, &port);
  if (!srv || port == 0) {
    std::fprintf(stderr, "fluxcal serve: cannot listen on %s\n", listen.c_str());
    return 1;
  }
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  // Never print a password from the URI.
  const std::string shown = (*store)->Backend() == "postgresql" ? "postgresql" : db;
  std::fprintf(stderr, "fluxcal serve: listening on %s (port %d), store %s\n", listen.c_str(), port, shown.c_str());
  std::fflush(stderr);
  std::thread waiter([&] { srv->Wait(); });
  while (!g_stop) std::this_thread::sleep_for(std::chrono::milliseconds(100));
  std::fprintf(stderr, "fluxcal serve: shutting down\n");
  srv->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(5));
  waiter.join();
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("serve", "run the gRPC calibration service (SQLite file or PostgreSQL)", RunServe);

}  // namespace fluxcal::cli
