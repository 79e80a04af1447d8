#include "pipeline/signing.h"

namespace fluxcal::pipeline {

absl::StatusOr<SigningKeyPair> GenerateSigningKeyPair() { return tables::GenerateEd25519(); }

absl::StatusOr<std::string> SigningKeyId(const std::string& public_pem) { return tables::KeyId(public_pem); }

absl::Status CheckSigningKey(const std::string& private_pem) { return tables::PublicPemOf(private_pem).status(); }

absl::StatusOr<std::string> SignExport(std::string_view data, const std::string& private_pem) {
  return tables::SignDetached(data, private_pem);
}

absl::Status VerifyExportSignature(std::string_view data, std::string_view sig_file, const std::string& public_pem) {
  return tables::VerifyDetached(data, sig_file, public_pem);
}

}  // namespace fluxcal::pipeline
