// The gRPC service: thin. Each handler converts protobuf to plain types,
// validates (server/validation.h), makes one call into pipeline/ and maps
// the status in one place (ToGrpcStatus).
// Stateless: everything lives in the store, so several servers may share
// one PostgreSQL database.
#ifndef FLUXCAL_SERVER_SERVICE_H_
#define FLUXCAL_SERVER_SERVICE_H_

#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "absl/status/status.h"
#include "fluxcal/v1/calibration.grpc.pb.h"
#include "server/auth.h"
#include "server/limits.h"
#include "pipeline/store.h"

namespace grpc {
class Server;
class Service;
}

namespace fluxcal::server {

grpc::Status ToGrpcStatus(const absl::Status& s);

// An authorized call: who makes it, and its place within that identity's
// limits (server/limits.h), given back when the handler returns.
struct Admission : Identity {
  IdentityLimiter::Lease lease;
};

class CalibrationServiceImpl final : public fluxcal::v1::CalibrationService::Service {
 public:
  explicit CalibrationServiceImpl(storage::Store* store) : store_(store) {}
  // Who may call what (server/auth.h). Without one the service is open.
  void set_authorizer(const Authorizer* auth) { auth_ = auth != nullptr ? auth : &open_; }
  // Ed25519 private key (PEM) that signs every ExportTable reply.
  void set_signing_key(std::string private_pem) { signing_key_pem_ = std::move(private_pem); }
  const Authorizer* authorizer() const { return auth_; }
  // After every write that moves a chain head (Fit, Diagnose with
  // store_calibration, Release), append an event line to this anchor file
  // (pipeline/anchor.h); empty: none.
  void set_anchor_file(std::string path) { anchor_file_ = std::move(path); }
  // Per-identity limits (server/limits.h); the defaults until set. Call
  // before the server starts.
  void set_limits(IdentityLimits limits) { limiter_ = std::make_unique<IdentityLimiter>(limits); }
  const IdentityLimiter& limiter() const { return *limiter_; }
  // Keeps a service registered beside this one (reflection) alive as long
  // as this one.
  void KeepAlive(std::unique_ptr<grpc::Service> s) { reflection_.push_back(std::move(s)); }

  grpc::Status IngestHfResults(grpc::ServerContext* ctx, grpc::ServerReader<v1::IngestHfResultsRequest>* reader,
                               v1::IngestHfResultsResponse* response) override;
  grpc::Status IngestRecording(grpc::ServerContext* ctx, grpc::ServerReader<v1::RecordingChunk>* reader,
                               v1::IngestRecordingResponse* response) override;
  grpc::Status Fit(grpc::ServerContext* ctx, const v1::FitRequest* req, v1::FitResponse* resp) override;
  grpc::Status GetCalibration(grpc::ServerContext* ctx, const v1::GetCalibrationRequest* req,
                              v1::CalibrationRecord* resp) override;
  grpc::Status ListMotors(grpc::ServerContext* ctx, const v1::ListMotorsRequest* req,
                          v1::ListMotorsResponse* resp) override;
  grpc::Status History(grpc::ServerContext* ctx, const v1::HistoryRequest* req, v1::HistoryResponse* resp) override;
  grpc::Status QueryFlux(grpc::ServerContext* ctx, const v1::QueryFluxRequest* req,
                         v1::QueryFluxResponse* resp) override;
  grpc::Status ExportTable(grpc::ServerContext* ctx, const v1::ExportTableRequest* req,
                           v1::ExportTableResponse* resp) override;
  grpc::Status FleetStatistics(grpc::ServerContext* ctx, const v1::FleetStatisticsRequest* req,
                               v1::FleetStatisticsResponse* resp) override;
  grpc::Status Diagnose(grpc::ServerContext* ctx, const v1::DiagnoseRequest* req, v1::DiagnoseResponse* resp) override;
  grpc::Status Release(grpc::ServerContext* ctx, const v1::ReleaseRequest* req, v1::ReleaseResponse* resp) override;
  grpc::Status Audit(grpc::ServerContext* ctx, const v1::AuditRequest* req, v1::AuditResponse* resp) override;
  grpc::Status GetReport(grpc::ServerContext* ctx, const v1::GetReportRequest* req,
                         v1::GetReportResponse* resp) override;

 private:
  // The audit row of a write, handed to the store, which inserts it in the
  // write's own transaction (both commit or neither); `detail` forms the
  // text from the run id or version written.
  // Authorize + a place in the caller's limits: UNAUTHENTICATED,
  // PERMISSION_DENIED or RESOURCE_EXHAUSTED.
  absl::StatusOr<Admission> Admit(grpc::ServerContext* ctx, Rpc rpc);
  // Admit, then the request's serial checked (INVALID_ARGUMENT naming it).
  absl::StatusOr<Admission> AdmitForSerial(grpc::ServerContext* ctx, Rpc rpc, const std::string& serial);
  storage::AuditContext AuditFor(grpc::ServerContext* ctx, const Identity& who, Rpc rpc, const std::string& serial,
                                 std::function<std::string(int64_t, bool)> detail);

  void AnchorAfterWrite(const std::string& serial);

  storage::Store* store_;
  std::string anchor_file_;
  Authorizer open_;
  const Authorizer* auth_ = &open_;
  std::unique_ptr<IdentityLimiter> limiter_ = std::make_unique<IdentityLimiter>();
  std::string signing_key_pem_;
  // Services registered beside this one by StartServer (this service
  // outlives its server, so they do too).
  std::vector<std::unique_ptr<grpc::Service>> reflection_;
};

struct ServerOptions {
  // TLS: PEM server certificate chain and private key; both empty means
  // plaintext. client_ca_pem non-empty requires and verifies client
  // certificates (mutual TLS) against it.
  std::string tls_cert_pem, tls_key_pem, client_ca_pem;
  // With client_ca_pem: refuse the handshake without a client certificate
  // (else a certificate is verified when presented and a token may stand
  // in for it).
  bool require_client_cert = false;
  // Server reflection v1 and v1alpha (server/reflection.h): for any
  // authenticated identity, every caller in open mode.
  bool reflection = true;
  // One log line per request on stderr: method, identity, peer, status,
  // latency.
  bool log_requests = false;
  const Authorizer* authorizer = nullptr;   // for the request log's identity
};

// Builds and starts a server (health checking and reflection on) listening
// on `address` ("127.0.0.1:50051"; port 0 picks one, returned in
// *bound_port). Messages up to kMaxMessageBytes (server/limits.h). With
// identities (the service's authorizer not open) every call is
// authenticated from its headers before its body is read
// (MakeAuthProcessor): over TLS, and on a loopback address (io/net.h) over
// gRPC's local credentials, which a plaintext client reaches as before;
// only a plaintext listener off loopback (`--insecure`) authenticates in
// the handler, after gRPC has read the first message.
std::unique_ptr<grpc::Server> StartServer(CalibrationServiceImpl* service, const std::string& address,
                                          int* bound_port, const ServerOptions& options = {});

}  // namespace fluxcal::server

#endif  // FLUXCAL_SERVER_SERVICE_H_
