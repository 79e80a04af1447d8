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
//   health    ListMotors only, answered with no rows: proves that the server
//             and its database answer (the container / systemd health check)
// Without a keys file the service runs open (every caller is "local" with
// the admin role); `fluxcal serve` allows that only on a loopback address.
//
// The keys file is re-read while the service runs: on Reload() (`fluxcal
// serve` calls it on SIGHUP) and when the file changes (its inode, size,
// mtime or ctime; looked at no more than once per check interval, 1 s by
// default, on the next call). A revoked token fails on its next call after
// that. A file that does not load keeps the keys loaded before (never opens
// the service) and is reported through the log callback.
#ifndef FLUXCAL_SERVER_AUTH_H_
#define FLUXCAL_SERVER_AUTH_H_

#include <atomic>
#include <chrono>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <grpcpp/support/string_ref.h>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace grpc {
class AuthContext;
class AuthMetadataProcessor;
class ServerContext;
}

namespace fluxcal::server {

enum class Role { kStation, kRelease, kFlasher, kEngineer, kAdmin, kHealth };
inline constexpr Role kAllRoles[] = {Role::kStation, Role::kRelease, Role::kFlasher,
                                     Role::kEngineer, Role::kAdmin,   Role::kHealth};
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

// Reads a keys file. InvalidArgument names file and field.
absl::StatusOr<Keys> LoadKeys(const std::string& path);
// Writes a keys file atomically (a temporary file beside it, fsync,
// rename), so a server re-reading it never sees half a file. A new file is
// mode 0600, owner only. A file that exists keeps its owner, group and mode
// (without permissions for others, and never executable), so a file made
// readable to the service's group stays readable to it. `group` non-empty
// (a name or a number) sets the group and mode 0640: the service user reads
// it, nobody else. InvalidArgument for an unknown group; PermissionDenied
// when the group or owner cannot be set (chown needs root or membership).
absl::Status SaveKeys(const std::string& path, const Keys& keys, const std::string& group = "");
// 32 random bytes (OpenSSL RAND_bytes) as 64 hex characters.
absl::StatusOr<std::string> NewToken();

struct Identity {
  std::string name;
  Role role = Role::kAdmin;
  std::string via;   // "token", "certificate" or "open"
};

using ClientMetadata = std::multimap<grpc::string_ref, grpc::string_ref>;

class Authorizer {
 public:
  using LogFn = std::function<void(const std::string&)>;
  // Open mode: every caller is {"local", admin, "open"}.
  Authorizer() = default;
  // Fixed keys (tests, tools).
  explicit Authorizer(Keys keys);
  // Keys read from `path` now, and again on Reload() or when the file
  // changes. `log` hears every reload and every failed one.
  static absl::StatusOr<std::unique_ptr<Authorizer>> FromFile(const std::string& path, LogFn log = nullptr);
  bool open() const { return open_; }

  // Re-reads the keys file now (for SIGHUP). On an error the keys loaded
  // before stay in force and the error is returned (and logged). OK without
  // a file (fixed keys, open mode).
  absl::Status Reload() const;
  // How often a call may look at the file's metadata (default 1 s; 0: on
  // every call).
  void set_check_interval(std::chrono::milliseconds interval) { check_interval_ns_ = interval.count() * 1000000; }
  size_t size() const;   // identities in force

  // The caller's identity: Unauthenticated when no or an unknown credential.
  absl::StatusOr<Identity> Authenticate(const grpc::ServerContext& ctx) const;
  // The same from the call's metadata and its connection's auth context (as
  // an AuthMetadataProcessor sees them, before the request body is read).
  absl::StatusOr<Identity> Authenticate(const ClientMetadata& metadata, const grpc::AuthContext* connection) const;
  // Authenticate + the role table: PermissionDenied names the identity, its
  // role and the RPC.
  absl::StatusOr<Identity> Authorize(const grpc::ServerContext& ctx, Rpc rpc) const;

 private:
  struct FileStamp {
    unsigned long long dev = 0, ino = 0;
    long long size = -1, mtime_ns = 0, ctime_ns = 0;
    bool operator==(const FileStamp&) const = default;
  };
  static FileStamp StampOf(const std::string& path);
  void MaybeReload() const;
  absl::Status ReloadLocked(const FileStamp& stamp) const;
  std::shared_ptr<const Keys> Current() const;

  bool open_ = true;
  std::string path_;   // empty: fixed keys or open
  LogFn log_;
  mutable std::mutex keys_mu_;
  mutable std::shared_ptr<const Keys> keys_ = std::make_shared<Keys>();
  mutable std::mutex reload_mu_;              // one reload at a time
  mutable FileStamp stamp_;                    // of the last reload attempt (guarded by reload_mu_)
  mutable std::atomic<long long> next_check_ns_{0};
  std::atomic<long long> check_interval_ns_{1000000000LL};
};

// Authenticates (and, for fluxcal.v1 methods, authorizes) every call from
// its metadata before gRPC reads the request body, so a caller without a
// valid credential never gets a message buffered: the call ends
// UNAUTHENTICATED / PERMISSION_DENIED right after its headers. Health
// checks (/grpc.health.v1.Health/) pass without a credential. For
// ServerCredentials::SetAuthMetadataProcessor (TLS or local credentials;
// gRPC 1.51's insecure credentials take none). `log` (may be null) hears
// each refusal.
std::shared_ptr<grpc::AuthMetadataProcessor> MakeAuthProcessor(const Authorizer* auth, Authorizer::LogFn log);

}  // namespace fluxcal::server

#endif  // FLUXCAL_SERVER_AUTH_H_
