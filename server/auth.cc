#include "server/auth.h"

#include <fcntl.h>
#include <grp.h>
#include <openssl/crypto.h>
#include <openssl/rand.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>

#include <grpcpp/grpcpp.h>
#include <grpcpp/security/auth_metadata_processor.h>

#include "absl/strings/ascii.h"
#include "absl/strings/escaping.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "io/csv.h"
#include "nlohmann/json.hpp"
#include "io/sha256.h"

namespace fluxcal::server {
namespace {

constexpr char kKeysFormat[] = "fluxcal.keys.v1";

std::string Hex(const unsigned char* p, size_t n) {
  return absl::BytesToHexString(absl::string_view(reinterpret_cast<const char*>(p), n));
}

}  // namespace

std::string_view RoleName(Role r) {
  switch (r) {
    case Role::kStation: return "station";
    case Role::kRelease: return "release";
    case Role::kFlasher: return "flasher";
    case Role::kEngineer: return "engineer";
    case Role::kAdmin: return "admin";
    case Role::kHealth: return "health";
  }
  return "?";
}

std::optional<Role> ParseRole(std::string_view name) {
  for (Role r : kAllRoles) {
    if (RoleName(r) == name) return r;
  }
  return std::nullopt;
}

std::string_view RpcName(Rpc r) {
  switch (r) {
    case Rpc::kIngestHfResults: return "IngestHfResults";
    case Rpc::kIngestRecording: return "IngestRecording";
    case Rpc::kFit: return "Fit";
    case Rpc::kGetCalibration: return "GetCalibration";
    case Rpc::kListMotors: return "ListMotors";
    case Rpc::kHistory: return "History";
    case Rpc::kQueryFlux: return "QueryFlux";
    case Rpc::kExportTable: return "ExportTable";
    case Rpc::kFleetStatistics: return "FleetStatistics";
    case Rpc::kDiagnose: return "Diagnose";
    case Rpc::kRelease: return "Release";
    case Rpc::kAudit: return "Audit";
    case Rpc::kGetReport: return "GetReport";
  }
  return "?";
}

bool RoleMayCall(Role role, Rpc rpc) {
  if (role == Role::kAdmin) return true;
  // A health check proves the server and its database answer; ListMotors
  // answers a health identity with no rows (server/read_rpcs.cc).
  if (role == Role::kHealth) return rpc == Rpc::kListMotors;
  switch (rpc) {
    case Rpc::kIngestHfResults:
    case Rpc::kIngestRecording:
      return role == Role::kStation;
    case Rpc::kFit:
      return role == Role::kStation || role == Role::kEngineer;
    case Rpc::kExportTable:
      return true;   // every role fetches tables (flashers only this)
    case Rpc::kGetCalibration:
    case Rpc::kGetReport:   // the stored calibration drawn: readers of it may read the page
    case Rpc::kQueryFlux:
      return role == Role::kEngineer || role == Role::kRelease || role == Role::kStation;
    case Rpc::kListMotors:
    case Rpc::kHistory:
      return role == Role::kEngineer || role == Role::kRelease;
    case Rpc::kFleetStatistics:
    case Rpc::kDiagnose:
      return role == Role::kEngineer;
    case Rpc::kRelease:
      return role == Role::kRelease;
    case Rpc::kAudit:
      return role == Role::kEngineer || role == Role::kRelease;
  }
  return false;
}

absl::StatusOr<std::string> NewToken() {
  unsigned char b[32];
  if (RAND_bytes(b, sizeof b) != 1) return absl::InternalError("OpenSSL RAND_bytes failed");
  return Hex(b, sizeof b);
}

absl::StatusOr<Keys> LoadKeys(const std::string& path) {
  auto text = io::ReadFileToString(path);
  if (!text.ok()) return text.status();
  auto bad = [&](const std::string& field, const std::string& what) {
    return absl::InvalidArgumentError(absl::StrCat(path, ": field '", field, "': ", what));
  };
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(*text);
  } catch (const nlohmann::json::exception& e) {
    return bad("(json)", io::Printable(e.what()));
  }
  if (!j.is_object() || j.value("format", "") != kKeysFormat) {
    return bad("format", absl::StrCat("expected \"", kKeysFormat, "\""));
  }
  Keys keys;
  if (!j.contains("keys") || !j["keys"].is_array()) return bad("keys", "expected an array");
  for (size_t k = 0; k < j["keys"].size(); ++k) {
    const auto& e = j["keys"][k];
    const std::string f = absl::StrCat("keys[", k, "]");
    if (!e.is_object()) return bad(f, "expected an object");
    KeyEntry ke;
    if (!e.contains("name") || !e["name"].is_string()) return bad(f + ".name", "expected a string");
    ke.name = e["name"].get<std::string>();
    if (!e.contains("role") || !e["role"].is_string()) return bad(f + ".role", "expected a string");
    auto role = ParseRole(e["role"].get<std::string>());
    if (!role) return bad(f + ".role", "one of station, release, flasher, engineer, admin, health");
    ke.role = *role;
    if (e.contains("token_sha256") && e["token_sha256"].is_string()) ke.token_sha256 = e["token_sha256"];
    if (e.contains("cert_cn") && e["cert_cn"].is_string()) ke.cert_cn = e["cert_cn"];
    if (ke.token_sha256.empty() == ke.cert_cn.empty()) {
      return bad(f, "exactly one of token_sha256 and cert_cn");
    }
    if (!ke.token_sha256.empty() && ke.token_sha256.size() != 64) return bad(f + ".token_sha256", "64 hex digits");
    keys.entries.push_back(std::move(ke));
  }
  return keys;
}

namespace {

absl::StatusOr<gid_t> GroupId(const std::string& group) {
  unsigned long n = 0;
  if (absl::SimpleAtoi(group, &n)) return static_cast<gid_t>(n);
  struct group g, *out = nullptr;
  std::vector<char> buf(16384);
  if (getgrnam_r(group.c_str(), &g, buf.data(), buf.size(), &out) != 0 || out == nullptr) {
    return absl::InvalidArgumentError(absl::StrCat("group '", io::Printable(group), "': no such group"));
  }
  return out->gr_gid;
}

}  // namespace

absl::Status SaveKeys(const std::string& path, const Keys& keys, const std::string& group) {
  nlohmann::json arr = nlohmann::json::array();
  for (const auto& e : keys.entries) {
    nlohmann::json o = {{"name", e.name}, {"role", std::string(RoleName(e.role))}};
    if (!e.token_sha256.empty()) o["token_sha256"] = e.token_sha256;
    if (!e.cert_cn.empty()) o["cert_cn"] = e.cert_cn;
    arr.push_back(o);
  }
  const std::string text = nlohmann::json{{"format", kKeysFormat}, {"keys", arr}}.dump(2) + "\n";
  // The file names who may do what: owner only, or owner and the service's
  // group; never others. A replaced file keeps its owner, group and mode.
  uid_t uid = ::geteuid();
  gid_t gid = ::getegid();
  mode_t mode = 0600;
  if (struct stat st; ::stat(path.c_str(), &st) == 0) {
    uid = st.st_uid;
    gid = st.st_gid;
    mode = (st.st_mode & 0660) | 0600;
  }
  if (!group.empty()) {
    auto g = GroupId(group);
    if (!g.ok()) return g.status();
    gid = *g;
    mode = 0640;
  }
  std::string tmp = path + ".XXXXXX";
  const int fd = ::mkstemp(tmp.data());   // mode 0600 whatever the umask
  if (fd < 0) return absl::PermissionDeniedError(absl::StrCat(path, ": cannot write beside it (", std::strerror(errno), ")"));
  auto fail = [&](absl::Status s) {
    ::close(fd);
    ::unlink(tmp.c_str());
    return s;
  };
  for (size_t off = 0; off < text.size();) {
    const ssize_t n = ::write(fd, text.data() + off, text.size() - off);
    if (n <= 0) return fail(absl::DataLossError(absl::StrCat(path, ": write failed (", std::strerror(errno), ")")));
    off += static_cast<size_t>(n);
  }
  if ((uid != ::geteuid() || gid != ::getegid()) &&
      ::fchown(fd, uid == ::geteuid() ? static_cast<uid_t>(-1) : uid, gid) != 0) {
    return fail(absl::PermissionDeniedError(absl::StrCat(
        path, ": cannot give the file owner ", uid, " and group ", gid, " (", std::strerror(errno),
        "): run as root, or as the owner and a member of the group")));
  }
  if (::fchmod(fd, mode) != 0 || ::fsync(fd) != 0) {
    return fail(absl::DataLossError(absl::StrCat(path, ": write failed (", std::strerror(errno), ")")));
  }
  ::close(fd);
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    ::unlink(tmp.c_str());
    return absl::DataLossError(absl::StrCat(path, ": rename failed (", std::strerror(errno), ")"));
  }
  // The rename itself durable: fsync the directory.
  std::string dir = std::filesystem::path(path).parent_path().string();
  if (dir.empty()) dir = ".";
  if (const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY); dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
  return absl::OkStatus();
}

Authorizer::Authorizer(Keys keys) : open_(false), keys_(std::make_shared<Keys>(std::move(keys))) {}

absl::StatusOr<std::unique_ptr<Authorizer>> Authorizer::FromFile(const std::string& path, LogFn log) {
  std::unique_ptr<Authorizer> a(new Authorizer());
  a->open_ = false;
  a->path_ = path;
  a->log_ = std::move(log);
  // The stamp before the read: a change during the read is seen next time.
  a->stamp_ = StampOf(path);
  auto keys = LoadKeys(path);
  if (!keys.ok()) return keys.status();
  a->keys_ = std::make_shared<Keys>(std::move(*keys));
  return a;
}

Authorizer::FileStamp Authorizer::StampOf(const std::string& path) {
  FileStamp f;
  struct stat st;
  if (::stat(path.c_str(), &st) != 0) return f;
  f.dev = st.st_dev;
  f.ino = st.st_ino;
  f.size = st.st_size;
  f.mtime_ns = st.st_mtim.tv_sec * 1000000000LL + st.st_mtim.tv_nsec;
  f.ctime_ns = st.st_ctim.tv_sec * 1000000000LL + st.st_ctim.tv_nsec;
  return f;
}

std::shared_ptr<const Keys> Authorizer::Current() const {
  std::lock_guard<std::mutex> l(keys_mu_);
  return keys_;
}

size_t Authorizer::size() const { return Current()->entries.size(); }

absl::Status Authorizer::ReloadLocked(const FileStamp& stamp) const {
  stamp_ = stamp;
  auto keys = LoadKeys(path_);
  const size_t before = size();
  if (!keys.ok()) {
    if (log_) {
      log_(absl::StrCat("keys file ", path_, " not reloaded: ", keys.status().message(), "; keeping the ", before,
                        " identities loaded before"));
    }
    return keys.status();
  }
  const size_t now = keys->entries.size();
  {
    std::lock_guard<std::mutex> l(keys_mu_);
    keys_ = std::make_shared<Keys>(std::move(*keys));
  }
  if (log_) log_(absl::StrCat("keys reloaded from ", path_, ": ", now, " identities (before: ", before, ")"));
  return absl::OkStatus();
}

absl::Status Authorizer::Reload() const {
  if (path_.empty()) return absl::OkStatus();
  std::lock_guard<std::mutex> l(reload_mu_);
  return ReloadLocked(StampOf(path_));
}

void Authorizer::MaybeReload() const {
  if (path_.empty()) return;
  const long long now = std::chrono::duration_cast<std::chrono::nanoseconds>(
                            std::chrono::steady_clock::now().time_since_epoch())
                            .count();
  if (now < next_check_ns_.load(std::memory_order_relaxed)) return;
  next_check_ns_.store(now + check_interval_ns_.load(std::memory_order_relaxed), std::memory_order_relaxed);
  std::unique_lock<std::mutex> l(reload_mu_, std::try_to_lock);
  if (!l.owns_lock()) return;   // another call is reloading
  const FileStamp stamp = StampOf(path_);
  if (stamp == stamp_) return;
  (void)ReloadLocked(stamp);   // logged; the keys before stay on an error
}

absl::StatusOr<Identity> Authorizer::Authenticate(const grpc::ServerContext& ctx) const {
  const std::shared_ptr<const grpc::AuthContext> ac = ctx.auth_context();
  return Authenticate(ctx.client_metadata(), ac.get());
}

absl::StatusOr<Identity> Authorizer::Authenticate(const ClientMetadata& md, const grpc::AuthContext* ac) const {
  if (open_) return Identity{"local", Role::kAdmin, "open"};
  MaybeReload();
  const std::shared_ptr<const Keys> keys = Current();
  auto it = md.find("authorization");
  if (it != md.end()) {
    const std::string_view v(it->second.data(), it->second.size());
    constexpr std::string_view kBearer = "Bearer ";
    if (v.substr(0, kBearer.size()) != kBearer) {
      return absl::UnauthenticatedError("authorization: expected 'Bearer <token>'");
    }
    const std::string h = io::Sha256Hex(v.substr(kBearer.size()));
    for (const auto& e : keys->entries) {
      if (e.token_sha256.size() == h.size() && CRYPTO_memcmp(e.token_sha256.data(), h.data(), h.size()) == 0) {
        return Identity{e.name, e.role, "token"};
      }
    }
    return absl::UnauthenticatedError("authorization: unknown or revoked token");
  }
  if (ac != nullptr && ac->IsPeerAuthenticated()) {
    for (const auto& cn : ac->FindPropertyValues("x509_common_name")) {
      const std::string name(cn.data(), cn.size());
      for (const auto& e : keys->entries) {
        if (!e.cert_cn.empty() && e.cert_cn == name) return Identity{e.name, e.role, "certificate"};
      }
      return absl::UnauthenticatedError(
          absl::StrCat("client certificate '", io::Printable(name), "' is not in the service's keys"));
    }
  }
  return absl::UnauthenticatedError(
      "no credential: send 'authorization: Bearer <token>' (fluxcal --token-file) or a client certificate");
}

namespace {

absl::Status MayCall(const Identity& id, Rpc rpc) {
  if (RoleMayCall(id.role, rpc)) return absl::OkStatus();
  return absl::PermissionDeniedError(absl::StrCat("'", id.name, "' (role ", std::string(RoleName(id.role)),
                                                  ") may not call ", std::string(RpcName(rpc))));
}

class AuthProcessor final : public grpc::AuthMetadataProcessor {
 public:
  AuthProcessor(const Authorizer* auth, Authorizer::LogFn log) : auth_(auth), log_(std::move(log)) {}
  // Quick (a hash, a stat at most once a second): runs on gRPC's thread.
  bool IsBlocking() const override { return false; }
  grpc::Status Process(const InputMetadata& md, grpc::AuthContext* connection, OutputMetadata*,
                       OutputMetadata*) override {
    std::string path;
    if (auto it = md.find(":path"); it != md.end()) path.assign(it->second.data(), it->second.size());
    constexpr std::string_view kHealth = "/grpc.health.v1.Health/";
    if (path.compare(0, kHealth.size(), kHealth) == 0) return grpc::Status::OK;
    absl::Status s;
    auto id = auth_->Authenticate(md, connection);
    if (!id.ok()) {
      s = id.status();
    } else {
      constexpr std::string_view kService = "/fluxcal.v1.CalibrationService/";
      if (path.compare(0, kService.size(), kService) == 0) {
        for (Rpc rpc : kAllRpcs) {
          if (path.substr(kService.size()) == RpcName(rpc)) s = MayCall(*id, rpc);
        }
      }
    }
    if (s.ok()) return grpc::Status::OK;
    const bool denied = s.code() == absl::StatusCode::kPermissionDenied;
    if (log_) {
      log_(absl::StrCat("rpc=", io::Printable(path.substr(0, 128)), " identity=",
                        id.ok() ? absl::StrCat(id->name, "/", std::string(RoleName(id->role))) : "-",
                        " peer=- status=", denied ? 7 : 16, " refused before the request body: ", s.message()));
    }
    return grpc::Status(denied ? grpc::StatusCode::PERMISSION_DENIED : grpc::StatusCode::UNAUTHENTICATED,
                        std::string(s.message()));
  }

 private:
  const Authorizer* auth_;
  Authorizer::LogFn log_;
};

}  // namespace

absl::StatusOr<Identity> Authorizer::Authorize(const grpc::ServerContext& ctx, Rpc rpc) const {
  auto id = Authenticate(ctx);
  if (!id.ok()) return id.status();
  if (auto s = MayCall(*id, rpc); !s.ok()) return s;
  return id;
}

std::shared_ptr<grpc::AuthMetadataProcessor> MakeAuthProcessor(const Authorizer* auth, Authorizer::LogFn log) {
  return std::make_shared<AuthProcessor>(auth, std::move(log));
}

}  // namespace fluxcal::server
