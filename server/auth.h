// Identity and roles for the service (deny by default).
//
// A caller is identified by a bearer token (metadata "authorization:
// Bearer <token>") or, on a mutual-TLS connection, by its client
// certificate's common name. Both are listed in a keys file
// (`fluxcal.keys.v1`, managed by `fluxcal admin add-key|add-cert|revoke|
// list-keys`): tokens only as SHA-256 hashes, each with a name and a role.
//
// Roles and what they may call (docs/service.md, "Roles"):
//   station   ingest HF results and recordings (as itself), fit, fetch tables
//   release   read, query, fetch tables, release a passing calibration
//   flasher   fetch released tables only
//   engineer  read, query, history, fleet statistics, diagnose, fit
//   admin     everything
// Without a keys file the service runs open (every caller is "local" with
// the admin role); `fluxcal serve` allows that only on a loopback address.
#ifndef FLUXCAL_SERVER_AUTH_H_
#define FLUXCAL_SERVER_AUTH_H_

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace grpc {
class ServerContext;
}

namespace fluxcal::server {

enum class Role { kStation, kRelease, kFlasher, kEngineer, kAdmin };
std::string_view RoleName(Role r);
std::optional<Role> ParseRole(std::string_view name);

enum class Rpc {
  kIngestHfResults, kIngestRecording, kFit, kGetCalibration, kListMotors, kHistory,
  kQueryFlux, kExportTable, kFleetStatistics, kDiagnose, kRelease, kAudit, kGetReport,
};
inline constexpr Rpc kAllRpcs[] = {Rpc::kIngestHfResults, Rpc::kIngestRecording, Rpc::kFit, Rpc::kGetCalibration,
                                   Rpc::kListMotors,      Rpc::kHistory,         Rpc::kQueryFlux,
                                   Rpc::kExportTable,     Rpc::kFleetStatistics, Rpc::kDiagnose,
                                   Rpc::kRelease,         Rpc::kAudit,           Rpc::kGetReport};
std::string_view RpcName(Rpc r);
// The permission table above, in one place.
bool RoleMayCall(Role role, Rpc rpc);

struct KeyEntry {
  std::string name;            // identity name, e.g. "station-07"
  Role role = Role::kEngineer;
  std::string token_sha256;    // hex; empty for a certificate entry
  std::string cert_cn;         // client certificate common name; empty for a token
};

struct Keys {
  std::vector<KeyEntry> entries;
};

// Reads / writes a keys file. InvalidArgument names file and field.
absl::StatusOr<Keys> LoadKeys(const std::string& path);
absl::Status SaveKeys(const std::string& path, const Keys& keys);   // atomic, mode 0600
// 32 random bytes (OpenSSL RAND_bytes) as 64 hex characters.
absl::StatusOr<std::string> NewToken();

struct Identity {
  std::string name;
  Role role = Role::kAdmin;
  std::string via;   // "token", "certificate" or "open"
};

class Authorizer {
 public:
  // Open mode: every caller is {"local", admin, "open"}.
  Authorizer() = default;
  explicit Authorizer(Keys keys) : keys_(std::move(keys)), open_(false) {}
  bool open() const { return open_; }

  // The caller's identity: Unauthenticated when no or an unknown credential.
  absl::StatusOr<Identity> Authenticate(const grpc::ServerContext& ctx) const;
  // Authenticate + the role table: PermissionDenied names the identity, its
  // role and the RPC.
  absl::StatusOr<Identity> Authorize(const grpc::ServerContext& ctx, Rpc rpc) const;

 private:
  Keys keys_;
  bool open_ = true;
};

}  // namespace fluxcal::server

#endif  // FLUXCAL_SERVER_AUTH_H_
