// A CalibrationServiceImpl on a fresh SQLite store, served on a free
// loopback port behind an Authorizer: the fixture the role and limit tests
// build their identities on.
#ifndef FLUXCAL_TESTS_SERVER_AUTHORIZED_SERVER_H_
#define FLUXCAL_TESTS_SERVER_AUTHORIZED_SERVER_H_

#include <filesystem>
#include <memory>
#include <string>

#include <grpcpp/grpcpp.h>

#include "server/auth.h"
#include "server/limits.h"
#include "server/service.h"
#include "storage/store.h"

namespace fluxcal::server::test_support {

struct AuthorizedServer {
  std::string db;
  std::unique_ptr<storage::Store> store;
  std::unique_ptr<CalibrationServiceImpl> service;
  std::unique_ptr<Authorizer> auth;
  std::unique_ptr<grpc::Server> server;
  int port = 0;

  // Serves a new store at db_path (an old one and its -wal, -shm removed)
  // to the identities of keys, with opt's other settings and, if given,
  // limits per identity.
  void Start(const std::string& db_path, const Keys& keys, ServerOptions opt = {},
             const IdentityLimits* limits = nullptr) {
    db = db_path;
    RemoveDb();
    store = std::move(*storage::Store::Open(db));
    service = std::make_unique<CalibrationServiceImpl>(store.get());
    auth = std::make_unique<Authorizer>(keys);
    service->set_authorizer(auth.get());
    if (limits != nullptr) service->set_limits(*limits);
    opt.authorizer = auth.get();
    server = StartServer(service.get(), "127.0.0.1:0", &port, opt);
  }
  ~AuthorizedServer() {
    if (server) server->Shutdown();
    store.reset();
    RemoveDb();
  }
  std::string addr() const { return "127.0.0.1:" + std::to_string(port); }

 private:
  void RemoveDb() const {
    for (auto sfx : {"", "-wal", "-shm"}) std::filesystem::remove(db + sfx);
  }
};

}  // namespace fluxcal::server::test_support

#endif  // FLUXCAL_TESTS_SERVER_AUTHORIZED_SERVER_H_
