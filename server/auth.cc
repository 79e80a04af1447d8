#include "server/auth.h"

#include <openssl/crypto.h>
#include <openssl/rand.h>
#include <sys/stat.h>

#include <fstream>

#include <grpcpp/grpcpp.h>

#include "absl/strings/ascii.h"
#include "absl/strings/escaping.h"
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
  }
  return "?";
}

std::optional<Role> ParseRole(std::string_view name) {
  for (Role r : {Role::kStation, Role::kRelease, Role::kFlasher, Role::kEngineer, Role::kAdmin}) {
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
    if (!role) return bad(f + ".role", "one of station, release, flasher, engineer, admin");
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

absl::Status SaveKeys(const std::string& path, const Keys& keys) {
  nlohmann::json arr = nlohmann::json::array();
  for (const auto& e : keys.entries) {
    nlohmann::json o = {{"name", e.name}, {"role", std::string(RoleName(e.role))}};
    if (!e.token_sha256.empty()) o["token_sha256"] = e.token_sha256;
    if (!e.cert_cn.empty()) o["cert_cn"] = e.cert_cn;
    arr.push_back(o);
  }
  const std::string text = nlohmann::json{{"format", kKeysFormat}, {"keys", arr}}.dump(2) + "\n";
  const mode_t old = ::umask(077);   // the file names who may do what: owner only
  auto s = io::WriteFileAtomically(path, text);
  ::umask(old);
  return s;
}

absl::StatusOr<Identity> Authorizer::Authenticate(const grpc::ServerContext& ctx) const {
  if (open_) return Identity{"local", Role::kAdmin, "open"};
  const auto& md = ctx.client_metadata();
  auto it = md.find("authorization");
  if (it != md.end()) {
    const std::string_view v(it->second.data(), it->second.size());
    constexpr std::string_view kBearer = "Bearer ";
    if (v.substr(0, kBearer.size()) != kBearer) {
      return absl::UnauthenticatedError("authorization: expected 'Bearer <token>'");
    }
    const std::string h = io::Sha256Hex(v.substr(kBearer.size()));
    for (const auto& e : keys_.entries) {
      if (e.token_sha256.size() == h.size() && CRYPTO_memcmp(e.token_sha256.data(), h.data(), h.size()) == 0) {
        return Identity{e.name, e.role, "token"};
      }
    }
    return absl::UnauthenticatedError("authorization: unknown or revoked token");
  }
  if (auto ac = ctx.auth_context(); ac && ac->IsPeerAuthenticated()) {
    for (const auto& cn : ac->FindPropertyValues("x509_common_name")) {
      const std::string name(cn.data(), cn.size());
      for (const auto& e : keys_.entries) {
        if (!e.cert_cn.empty() && e.cert_cn == name) return Identity{e.name, e.role, "certificate"};
      }
      return absl::UnauthenticatedError(
          absl::StrCat("client certificate '", io::Printable(name), "' is not in the service's keys"));
    }
  }
  return absl::UnauthenticatedError(
      "no credential: send 'authorization: Bearer <token>' (fluxcal --token-file) or a client certificate");
}

absl::StatusOr<Identity> Authorizer::Authorize(const grpc::ServerContext& ctx, Rpc rpc) const {
  auto id = Authenticate(ctx);
  if (!id.ok()) return id.status();
  if (!RoleMayCall(id->role, rpc)) {
    return absl::PermissionDeniedError(absl::StrCat("'", id->name, "' (role ", std::string(RoleName(id->role)),
                                                    ") may not call ", std::string(RpcName(rpc))));
  }
  return id;
}

}  // namespace fluxcal::server
