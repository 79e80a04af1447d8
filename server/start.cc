// Starting the server: credentials (TLS, local, or insecure), the
// authentication processor, flow-control and size limits, reflection, and
// the per-request log line.
#include "server/service.h"

#include <grpcpp/health_check_service_interface.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/support/server_interceptor.h>

#include <chrono>
#include <cstdio>

#include "absl/strings/str_cat.h"
#include "io/net.h"
#include "pipeline/pipeline.h"
#include "server/reflection.h"

namespace fluxcal::server {

namespace {

// One stderr line per request: method, identity, peer, status, latency.
class RequestLog final : public grpc::experimental::Interceptor {
 public:
  RequestLog(grpc::experimental::ServerRpcInfo* info, const Authorizer* auth)
      : info_(info), auth_(auth), start_(std::chrono::steady_clock::now()) {}
  void Intercept(grpc::experimental::InterceptorBatchMethods* m) override {
    if (m->QueryInterceptionHookPoint(grpc::experimental::InterceptionHookPoints::PRE_SEND_STATUS)) {
      const grpc::Status st = m->GetSendStatus();
      const grpc::ServerContextBase* base = info_->server_context();
      std::string who = "-", peer = "-";
      if (const auto* ctx = dynamic_cast<const grpc::ServerContext*>(base)) {
        if (auto id = auth_->Authenticate(*ctx); id.ok()) who = absl::StrCat(id->name, "/", std::string(RoleName(id->role)));
        peer = ctx->peer();
      }
      const double ms =
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start_).count();
      std::fprintf(stderr, "fluxcal serve: rpc=%s identity=%s peer=%s status=%d latency_ms=%.1f\n", info_->method(),
                   who.c_str(), peer.c_str(), static_cast<int>(st.error_code()), ms);
    }
    m->Proceed();
  }

 private:
  grpc::experimental::ServerRpcInfo* info_;
  const Authorizer* auth_;
  std::chrono::steady_clock::time_point start_;
};

class RequestLogFactory final : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit RequestLogFactory(const Authorizer* auth) : auth_(auth) {}
  grpc::experimental::Interceptor* CreateServerInterceptor(grpc::experimental::ServerRpcInfo* info) override {
    return new RequestLog(info, auth_);
  }

 private:
  const Authorizer* auth_;
};

}  // namespace

std::unique_ptr<grpc::Server> StartServer(CalibrationServiceImpl* service, const std::string& address,
                                          int* bound_port, const ServerOptions& options) {
  grpc::EnableDefaultHealthCheckService(true);
  ReturnLargeBlocksWhenFreed();
  grpc::ServerBuilder b;
  const Authorizer* auth = service->authorizer();
  std::shared_ptr<grpc::ServerCredentials> creds;
  bool takes_processor = true;
  if (!options.tls_cert_pem.empty()) {
    grpc::SslServerCredentialsOptions ssl(
        options.client_ca_pem.empty() ? GRPC_SSL_DONT_REQUEST_CLIENT_CERTIFICATE
        : options.require_client_cert ? GRPC_SSL_REQUEST_AND_REQUIRE_CLIENT_CERTIFICATE_AND_VERIFY
                                      : GRPC_SSL_REQUEST_CLIENT_CERTIFICATE_AND_VERIFY);
    ssl.pem_root_certs = options.client_ca_pem;
    ssl.pem_key_cert_pairs.push_back({options.tls_key_pem, options.tls_cert_pem});
    creds = grpc::SslServerCredentials(ssl);
  } else if (!auth->open() && io::IsLoopbackAddress(address)) {
    // Plaintext on the wire as before, but gRPC's local credentials take an
    // AuthMetadataProcessor (its insecure ones do not) and refuse peers
    // that are not on this machine.
    creds = grpc::experimental::LocalServerCredentials(address.rfind("unix", 0) == 0 ? UDS : LOCAL_TCP);
  } else {
    creds = grpc::InsecureServerCredentials();
    takes_processor = false;
  }
  if (!auth->open() && takes_processor) {
    Authorizer::LogFn log;
    if (options.log_requests) log = [](const std::string& m) { std::fprintf(stderr, "fluxcal serve: %s\n", m.c_str()); };
    creds->SetAuthMetadataProcessor(MakeAuthProcessor(auth, std::move(log)));
  }
  // No SO_REUSEPORT (gRPC's default on Linux): a second `fluxcal serve` on
  // a port already in use must fail to start, not silently take half of
  // the connections to its own store.
  b.AddChannelArgument(GRPC_ARG_ALLOW_REUSEPORT, 0);
  // HTTP/2 flow control without BDP probing: a stream's window stays at
  // 64 KiB ahead of what its handler reads (the handler's read of a message
  // opens the window for that message). With probing, gRPC grows windows
  // to megabytes, and a whole unauthenticated message reached the server
  // before the call was refused (measured: tests/server/ops_test, PreAuth).
  b.AddChannelArgument(GRPC_ARG_HTTP2_BDP_PROBE, 0);
  b.AddListeningPort(address, creds, bound_port);
  b.RegisterService(service);
  if (options.reflection) {
    auto refl = MakeReflectionServices(service->authorizer(),
                                       {v1::CalibrationService::service_full_name(), "grpc.health.v1.Health"});
    for (auto& r : refl) {
      b.RegisterService(r.get());
      service->KeepAlive(std::move(r));
    }
  }
  // Small messages: no legitimate request is larger (server/limits.h).
  b.SetMaxReceiveMessageSize(kMaxMessageBytes);
  if (options.log_requests) {
    static const Authorizer kOpen;
    std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> creators;
    creators.push_back(std::make_unique<RequestLogFactory>(options.authorizer ? options.authorizer : &kOpen));
    b.experimental().SetInterceptorCreators(std::move(creators));
  }
  return b.BuildAndStart();
}

}  // namespace fluxcal::server
