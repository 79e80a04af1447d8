// fluxcal verify FILE --pubkey KEY.pub [--sig FILE.sig] [--json]
// Checks a table file against its detached Ed25519 signature
// (pipeline/signing.h). Exit 0: valid; 1: not valid (the reason on stderr,
// and in the JSON document); 2: usage.
#include <cstdio>

#include "cli/args.h"
#include "cli/command.h"
#include "cli/support_output.h"
#include "io/csv.h"
#include "nlohmann/json.hpp"
#include "pipeline/signing.h"

namespace fluxcal::cli {
namespace {

constexpr char kVerifyUsage[] = "fluxcal verify FILE --pubkey KEY.pub [--sig FILE.sig] [--json]";
const FlagSpecs kVerifyFlags = {
    {"pubkey", "KEY.pub", "Ed25519 public key PEM (fluxcal admin keygen; required)"},
    {"sig", "FILE", "detached signature (default FILE.sig)"},
    kJsonFlag,
};

int RunVerify(const std::vector<std::string>& argv) {
  auto args = ParseArgs(argv, kVerifyFlags);
  if (!args.ok() || args->positional.size() != 1 || !args->Get("pubkey")) return UsageError(kVerifyUsage);
  const std::string file = args->positional[0];
  const std::string sig_path = args->Get("sig").value_or(file + ".sig");
  absl::Status st;
  auto data = io::ReadFileToString(file);
  auto sig = io::ReadFileToString(sig_path);
  auto pub = io::ReadFileToString(*args->Get("pubkey"));
  if (!data.ok()) st = data.status();
  else if (!sig.ok()) st = absl::NotFoundError(sig_path + ": signature file not found");
  else if (!pub.ok()) st = pub.status();
  else st = pipeline::VerifyExportSignature(*data, *sig, *pub);
  if (args->Has("json")) {
    nlohmann::json j = {{"file", file}, {"signature", sig_path}, {"valid", st.ok()}};
    if (!st.ok()) j["error"] = std::string(st.message());
    if (pub.ok()) {
      if (auto id = pipeline::SigningKeyId(*pub); id.ok()) j["key_id"] = *id;
    }
    PrintJson(j);
  } else if (st.ok()) {
    std::printf("%s: signature valid\n", file.c_str());
  }
  return st.ok() ? 0 : CommandError("verify", file + ": " + std::string(st.message()));
}

}  // namespace

FLUXCAL_REGISTER_COMMAND("verify", "check an exported table against its Ed25519 signature", RunVerify, kVerifyUsage,
                         kVerifyFlags);

}  // namespace fluxcal::cli
