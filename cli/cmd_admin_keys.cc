// fluxcal admin add-key|add-cert|revoke|list-keys --keys KEYS.json ...
// Manages the identities `fluxcal serve --auth KEYS.json` accepts
// (server/auth.h). A token is printed once, when it is made; the file keeps
// only its SHA-256. The file is replaced atomically and keeps its owner,
// group and mode; --group GROUP makes it mode 0640 in that group, so the
// service user reads it (docs/security.md). A running server picks up the
// change within a second, or at once on SIGHUP.
#include <cstdio>

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "io/csv.h"
#include "io/recording_set.h"
#include "nlohmann/json.hpp"
#include <sys/stat.h>

#include "pipeline/signing.h"
#include "server/auth.h"
#include "io/sha256.h"

namespace fluxcal::cli {
namespace {

// An existing keys file, or an empty set when it does not exist yet.
absl::StatusOr<server::Keys> LoadOrEmpty(const std::string& path) {
  if (!io::ReadFileToString(path).ok()) return server::Keys{};
  return server::LoadKeys(path);
}

int Fail(const char* cmd, const absl::Status& s) {
  std::fprintf(stderr, "fluxcal admin %s: %s\n", cmd, std::string(s.message()).c_str());
  return 1;
}

constexpr char kGroupHelp[] =
    "group of the service user (name or number): the keys file becomes mode 0640 in it (default: a new file is "
    "0600, an existing one keeps its owner, group and mode)";
const FlagSpec kKeysFlag = {"keys", "KEYS.json", "the keys file of `fluxcal serve --auth`"};
const FlagSpec kNewKeysFlag = {"keys", "KEYS.json", kKeysFlag.help + " (created if missing)"};
const FlagSpec kGroupFlag = {"group", "GROUP", kGroupHelp};
// add-key and add-cert: who, with which role (add-cert: and its certificate).
const FlagSpec kNameFlag = {"name", "NAME", "identity (unique in the keys file; logged in the audit trail)"};
const FlagSpec kRoleFlag = {"role", "ROLE", "station|release|flasher|engineer|admin|health"};
const FlagSpec kCnFlag = {"cn", "CN", "the client certificate's subject common name"};
const FlagSpecs kAddKeyFlags = {kNewKeysFlag, kNameFlag, kRoleFlag, kGroupFlag, kJsonFlag};
const FlagSpecs kAddCertFlags = {kNewKeysFlag, kNameFlag, kRoleFlag, kCnFlag, kGroupFlag, kJsonFlag};
const FlagSpecs kRevokeFlags = {kKeysFlag, {"name", "NAME", "identity to remove"}, kGroupFlag, kJsonFlag};
const FlagSpecs kListKeysFlags = {kKeysFlag, kJsonFlag};
const FlagSpecs kKeygenFlags = {
    {"out", "PREFIX", "writes PREFIX.key (private, for serve --signing-key / export --sign-key) and PREFIX.pub"},
    kJsonFlag,
    kForceFlag,
};
constexpr char kRevokeUsage[] = "fluxcal admin revoke --keys KEYS.json --name NAME [--group GROUP] [--json]";
constexpr char kListKeysUsage[] = "fluxcal admin list-keys --keys KEYS.json [--json]";
constexpr char kKeygenUsage[] = "fluxcal admin keygen --out PREFIX [--force] [--json]";

int AddEntry(const std::vector<std::string>& argv, bool cert) {
  const char* cmd = cert ? "add-cert" : "add-key";
  auto args = ParseArgs(argv, cert ? kAddCertFlags : kAddKeyFlags);
  if (!args.ok() || !args->Get("keys") || !args->Get("name") || !args->Get("role") || (cert && !args->Get("cn"))) {
    std::fprintf(stderr, "usage: fluxcal admin %s --keys KEYS.json --name NAME --role %s%s [--group GROUP] [--json]\n",
                 cmd, "station|release|flasher|engineer|admin|health", cert ? " --cn CERT_COMMON_NAME" : "");
    return 2;
  }
  auto role = server::ParseRole(*args->Get("role"));
  if (!role) {
    return Fail(cmd, absl::InvalidArgumentError("--role: one of station, release, flasher, engineer, admin, health"));
  }
  const std::string name = *args->Get("name");
  if (!io::IsValidSerial(name)) {
    return Fail(cmd, absl::InvalidArgumentError("--name: 1 to 64 characters of A-Z a-z 0-9 - _ ."));
  }
  auto keys = LoadOrEmpty(*args->Get("keys"));
  if (!keys.ok()) return Fail(cmd, keys.status());
  for (const auto& e : keys->entries) {
    if (e.name == name) return Fail(cmd, absl::AlreadyExistsError("--name: '" + name + "' exists (revoke it first)"));
  }
  server::KeyEntry e;
  e.name = name;
  e.role = *role;
  std::string token;
  if (cert) {
    e.cert_cn = *args->Get("cn");
  } else {
    auto t = server::NewToken();
    if (!t.ok()) return Fail(cmd, t.status());
    token = *t;
    e.token_sha256 = io::Sha256Hex(token);
  }
  keys->entries.push_back(e);
  if (auto s = server::SaveKeys(*args->Get("keys"), *keys, args->Get("group").value_or("")); !s.ok()) {
    return Fail(cmd, s);
  }
  if (args->Has("json")) {
    nlohmann::json j = {{"name", name}, {"role", std::string(server::RoleName(*role))}};
    if (cert) j["cert_cn"] = e.cert_cn; else j["token"] = token;
    PrintJson(j);
  } else if (cert) {
    std::printf("%s (%s): client certificate CN '%s'\n", name.c_str(), std::string(server::RoleName(*role)).c_str(),
                e.cert_cn.c_str());
  } else {
    std::fprintf(stderr, "token for %s (%s), shown once; store it in a file for --token-file:\n", name.c_str(),
                 std::string(server::RoleName(*role)).c_str());
    std::printf("%s\n", token.c_str());
  }
  return 0;
}

int RunAddKey(const std::vector<std::string>& argv) { return AddEntry(argv, false); }
int RunAddCert(const std::vector<std::string>& argv) { return AddEntry(argv, true); }

int RunRevoke(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kRevokeFlags);
  if (!args.ok() || !args->Get("keys") || !args->Get("name")) return UsageError(kRevokeUsage);
  auto keys = server::LoadKeys(*args->Get("keys"));
  if (!keys.ok()) return Fail("revoke", keys.status());
  const size_t before = keys->entries.size();
  std::erase_if(keys->entries, [&](const server::KeyEntry& e) { return e.name == *args->Get("name"); });
  if (keys->entries.size() == before) {
    return Fail("revoke", absl::NotFoundError("--name: '" + *args->Get("name") + "' is not in the keys"));
  }
  if (auto s = server::SaveKeys(*args->Get("keys"), *keys, args->Get("group").value_or("")); !s.ok()) {
    return Fail("revoke", s);
  }
  if (args->Has("json")) {
    PrintJson({{"revoked", *args->Get("name")}});
  } else {
    std::printf("revoked %s (a running server drops it within a second, or at once on SIGHUP)\n",
                args->Get("name")->c_str());
  }
  return 0;
}

int RunListKeys(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kListKeysFlags);
  if (!args.ok() || !args->Get("keys")) return UsageError(kListKeysUsage);
  auto keys = server::LoadKeys(*args->Get("keys"));
  if (!keys.ok()) return Fail("list-keys", keys.status());
  nlohmann::json arr = nlohmann::json::array();
  for (const auto& e : keys->entries) {
    arr.push_back({{"name", e.name}, {"role", std::string(server::RoleName(e.role))},
                   {"credential", e.cert_cn.empty() ? "token" : "certificate"}, {"cert_cn", e.cert_cn}});
    if (!args->Has("json")) {
      std::printf("%-24s %-9s %s\n", e.name.c_str(), std::string(server::RoleName(e.role)).c_str(),
                  e.cert_cn.empty() ? "token" : ("certificate CN " + e.cert_cn).c_str());
    }
  }
  if (args->Has("json")) PrintJson({{"keys", arr}});
  return 0;
}

int RunKeygen(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kKeygenFlags);
  if (!args.ok() || !args->Get("out")) return UsageError(std::string(kKeygenUsage) + "   (writes PREFIX.key, PREFIX.pub)");
  const std::string key = *args->Get("out") + ".key", pub = *args->Get("out") + ".pub";
  // The overwrite rule (cli/args.h): a key pair in use is never replaced
  // unless --force says so.
  if (auto e = CheckOverwrite(*args, {{"out", key}, {"out", pub}}); !e.empty()) {
    return Fail("keygen", absl::AlreadyExistsError(e));
  }
  auto kp = pipeline::GenerateSigningKeyPair();
  if (!kp.ok()) return Fail("keygen", kp.status());
  const mode_t old = ::umask(077);
  auto s = WriteNewOutput(*args, {"out", key}, kp->private_pem);
  ::umask(old);
  if (!s.ok()) return Fail("keygen", s);
  if (auto s2 = WriteNewOutput(*args, {"out", pub}, kp->public_pem); !s2.ok()) return Fail("keygen", s2);
  auto id = pipeline::SigningKeyId(kp->public_pem);
  if (args->Has("json")) {
    PrintJson({{"private_key", key}, {"public_key", pub}, {"key_id", id.value_or("")}});
  } else {
    std::printf("%s (private, keep on the server), %s (public, give to flashers), key id %s\n", key.c_str(),
                pub.c_str(), id.value_or("?").c_str());
  }
  return 0;
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("admin keygen", "make an Ed25519 key pair for signing exports", RunKeygen, kKeygenUsage,
                         kKeygenFlags);
FLUXCAL_REGISTER_COMMAND("admin add-key", "make a bearer token for an identity with a role (printed once)",
                         RunAddKey,
                         "fluxcal admin add-key --keys KEYS.json --name NAME --role ROLE [--group GROUP] [--json]",
                         kAddKeyFlags);
FLUXCAL_REGISTER_COMMAND("admin add-cert", "accept a client certificate common name with a role", RunAddCert,
                         "fluxcal admin add-cert --keys KEYS.json --name NAME --role ROLE --cn CERT_COMMON_NAME\n"
                         "  [--group GROUP] [--json]",
                         kAddCertFlags);
FLUXCAL_REGISTER_COMMAND("admin revoke", "remove an identity from a keys file", RunRevoke, kRevokeUsage,
                         kRevokeFlags);
FLUXCAL_REGISTER_COMMAND("admin list-keys", "list identities and roles of a keys file", RunListKeys, kListKeysUsage,
                         kListKeysFlags);

}  // namespace fluxcal::cli
