#include "pipeline/signing.h"

#include "tables/signature.h"

namespace fluxcal::pipeline {

absl::StatusOr<SigningKeyPair> GenerateSigningKeyPair() {
  auto kp = tables::GenerateEd25519();
  if (!kp.ok()) return kp.status();
  return SigningKeyPair{std::move(kp->private_pem), std::move(kp->public_pem)};
}

absl::StatusOr<std::string> SigningKeyId(const std::string& public_pem) { return tables::KeyId(public_pem); }

absl::Status CheckSigningKey(const std::string& private_pem) { return tables::PublicPemOf(private_pem).status(); }

absl::StatusOr<std::string> SignExport(std::string_view data, const std::string& private_pem) {
  return tables::SignDetached(data, private_pem);
}

absl::Status VerifyExportSignature(std::string_view data, std::string_view sig_file, const std::string& public_pem) {
  return tables::VerifyDetached(data, sig_file, public_pem);
}

}  // namespace fluxcal::pipeline
