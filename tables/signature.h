// Signed exports: Ed25519 (RFC 8032) through OpenSSL's libcrypto. A table
// file travels with a detached signature file (FILE.sig):
//
//   fluxcal-signature-v1 ed25519
//   key_id <first 16 hex digits of SHA-256 of the public key (DER)>
//   sha256 <hex digest of the file>
//   signature <base64 of the 64-byte signature over the file's bytes>
//
// `fluxcal verify FILE --pubkey KEY.pub` checks it; `fluxcal admin keygen`
// makes a key pair (PEM, PKCS#8 / SubjectPublicKeyInfo).
#ifndef FLUXCAL_TABLES_SIGNATURE_H_
#define FLUXCAL_TABLES_SIGNATURE_H_

#include <string>
#include <string_view>

#include "absl/status/statusor.h"

namespace fluxcal::tables {

struct KeyPairPem {
  std::string private_pem, public_pem;
};
absl::StatusOr<KeyPairPem> GenerateEd25519();

// The public key of a private key (both PEM).
absl::StatusOr<std::string> PublicPemOf(const std::string& private_pem);
absl::StatusOr<std::string> KeyId(const std::string& public_pem);

// The signature file for `data` (format above).
absl::StatusOr<std::string> SignDetached(std::string_view data, const std::string& private_pem);
// OK when `sig_file` is a valid signature of `data` by `public_pem`;
// InvalidArgument (malformed signature file), PermissionDenied (wrong key,
// changed data) otherwise, with the reason.
absl::Status VerifyDetached(std::string_view data, std::string_view sig_file, const std::string& public_pem);

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TABLES_SIGNATURE_H_
