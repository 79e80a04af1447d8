// Signed exports as cli/ and server/ use them: a key pair for `fluxcal admin
// keygen`, the detached signature of an exported table (the service's
// ExportTable with a signing key, `fluxcal export --sign-key`) and its check
// (`fluxcal verify`). The signature file's format and the Ed25519 calls are
// tables/signature.h's; these are the use cases over it.
#ifndef FLUXCAL_PIPELINE_SIGNING_H_
#define FLUXCAL_PIPELINE_SIGNING_H_

#include <string>
#include <string_view>

#include "absl/status/status.h"
#include "absl/status/statusor.h"
#include "tables/signature.h"

namespace fluxcal::pipeline {

// private_pem, public_pem.
using SigningKeyPair = tables::KeyPairPem;
// A new Ed25519 key pair (PEM, PKCS#8 / SubjectPublicKeyInfo).
absl::StatusOr<SigningKeyPair> GenerateSigningKeyPair();
// The key id of a public key (first 16 hex digits of SHA-256 of its DER).
absl::StatusOr<std::string> SigningKeyId(const std::string& public_pem);
// OK when `private_pem` is a usable signing key (its public key derives).
absl::Status CheckSigningKey(const std::string& private_pem);
// The detached signature file of `data` (an exported table's bytes).
absl::StatusOr<std::string> SignExport(std::string_view data, const std::string& private_pem);
// tables::VerifyDetached: OK, InvalidArgument (malformed signature file)
// or PermissionDenied (wrong key, changed data), with the reason.
absl::Status VerifyExportSignature(std::string_view data, std::string_view sig_file, const std::string& public_pem);

}  // namespace fluxcal::pipeline

#endif  // FLUXCAL_PIPELINE_SIGNING_H_
