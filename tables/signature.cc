#include "tables/signature.h"

#include <openssl/bio.h>
#include <openssl/evp.h>
#include <openssl/pem.h>
#include <openssl/x509.h>

#include <memory>
#include <vector>

#include "absl/strings/escaping.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"
#include "io/sha256.h"

namespace fluxcal::tables {
namespace {

struct PkeyFree { void operator()(EVP_PKEY* p) const { EVP_PKEY_free(p); } };
struct BioFree { void operator()(BIO* b) const { BIO_free(b); } };
struct CtxFree { void operator()(EVP_MD_CTX* c) const { EVP_MD_CTX_free(c); } };
using Pkey = std::unique_ptr<EVP_PKEY, PkeyFree>;

std::string BioString(BIO* b) {
  char* p = nullptr;
  const long n = BIO_get_mem_data(b, &p);
  return std::string(p, static_cast<size_t>(n));
}

absl::StatusOr<Pkey> ReadKey(const std::string& pem, bool priv) {
  std::unique_ptr<BIO, BioFree> b(BIO_new_mem_buf(pem.data(), static_cast<int>(pem.size())));
  Pkey k(priv ? PEM_read_bio_PrivateKey(b.get(), nullptr, nullptr, nullptr)
              : PEM_read_bio_PUBKEY(b.get(), nullptr, nullptr, nullptr));
  if (!k || EVP_PKEY_get_id(k.get()) != EVP_PKEY_ED25519) {
    return absl::InvalidArgumentError(priv ? "not an Ed25519 private key (PEM)" : "not an Ed25519 public key (PEM)");
  }
  return k;
}

absl::StatusOr<std::string> PublicPem(EVP_PKEY* k) {
  std::unique_ptr<BIO, BioFree> b(BIO_new(BIO_s_mem()));
  if (PEM_write_bio_PUBKEY(b.get(), k) != 1) return absl::InternalError("OpenSSL: cannot write public key");
  return BioString(b.get());
}

}  // namespace

absl::StatusOr<KeyPairPem> GenerateEd25519() {
  Pkey k(EVP_PKEY_Q_keygen(nullptr, nullptr, "ED25519"));
  if (!k) return absl::InternalError("OpenSSL: Ed25519 key generation failed");
  std::unique_ptr<BIO, BioFree> b(BIO_new(BIO_s_mem()));
  if (PEM_write_bio_PrivateKey(b.get(), k.get(), nullptr, nullptr, 0, nullptr, nullptr) != 1) {
    return absl::InternalError("OpenSSL: cannot write private key");
  }
  KeyPairPem out;
  out.private_pem = BioString(b.get());
  auto pub = PublicPem(k.get());
  if (!pub.ok()) return pub.status();
  out.public_pem = *pub;
  return out;
}

absl::StatusOr<std::string> PublicPemOf(const std::string& private_pem) {
  auto k = ReadKey(private_pem, true);
  if (!k.ok()) return k.status();
  return PublicPem(k->get());
}

absl::StatusOr<std::string> KeyId(const std::string& public_pem) {
  auto k = ReadKey(public_pem, false);
  if (!k.ok()) return k.status();
  unsigned char* der = nullptr;
  const int n = i2d_PUBKEY(k->get(), &der);
  if (n <= 0) return absl::InternalError("OpenSSL: cannot encode public key");
  std::string id = io::Sha256Hex(std::string_view(reinterpret_cast<const char*>(der), static_cast<size_t>(n)));
  OPENSSL_free(der);
  return id.substr(0, 16);
}

absl::StatusOr<std::string> SignDetached(std::string_view data, const std::string& private_pem) {
  auto k = ReadKey(private_pem, true);
  if (!k.ok()) return k.status();
  std::unique_ptr<EVP_MD_CTX, CtxFree> ctx(EVP_MD_CTX_new());
  unsigned char sig[64];
  size_t len = sizeof sig;
  // Ed25519 is one-shot over the whole message (no digest; RFC 8032 5.1.6).
  if (EVP_DigestSignInit(ctx.get(), nullptr, nullptr, nullptr, k->get()) != 1 ||
      EVP_DigestSign(ctx.get(), sig, &len, reinterpret_cast<const unsigned char*>(data.data()), data.size()) != 1) {
    return absl::InternalError("OpenSSL: Ed25519 signing failed");
  }
  auto pub = PublicPem(k->get());
  if (!pub.ok()) return pub.status();
  auto id = KeyId(*pub);
  if (!id.ok()) return id.status();
  return absl::StrCat("fluxcal-signature-v1 ed25519\nkey_id ", *id, "\nsha256 ", io::Sha256Hex(data), "\nsignature ",
                      absl::Base64Escape(absl::string_view(reinterpret_cast<const char*>(sig), len)), "\n");
}

absl::Status VerifyDetached(std::string_view data, std::string_view sig_file, const std::string& public_pem) {
  std::string key_id, sha, sig_b64;
  std::vector<std::string> lines = absl::StrSplit(absl::string_view(sig_file.data(), sig_file.size()), '\n',
                                                   absl::SkipEmpty());
  if (lines.empty() || lines[0] != "fluxcal-signature-v1 ed25519") {
    return absl::InvalidArgumentError("signature file: line 1: expected 'fluxcal-signature-v1 ed25519'");
  }
  for (size_t k = 1; k < lines.size(); ++k) {
    const auto sp = lines[k].find(' ');
    const std::string key = lines[k].substr(0, sp), value = sp == std::string::npos ? "" : lines[k].substr(sp + 1);
    if (key == "key_id") key_id = value;
    else if (key == "sha256") sha = value;
    else if (key == "signature") sig_b64 = value;
    else return absl::InvalidArgumentError(absl::StrCat("signature file: line ", k + 1, ": unknown field"));
  }
  std::string sig;
  if (sig_b64.empty() || !absl::Base64Unescape(sig_b64, &sig) || sig.size() != 64) {
    return absl::InvalidArgumentError("signature file: field 'signature': expected base64 of 64 bytes");
  }
  auto k = ReadKey(public_pem, false);
  if (!k.ok()) return k.status();
  auto id = KeyId(public_pem);
  if (!id.ok()) return id.status();
  if (key_id != *id) {
    return absl::PermissionDeniedError(absl::StrCat("signed by key ", key_id, ", not by this key (", *id, ")"));
  }
  if (sha != io::Sha256Hex(data)) return absl::PermissionDeniedError("the file changed after signing (SHA-256 differs)");
  std::unique_ptr<EVP_MD_CTX, CtxFree> ctx(EVP_MD_CTX_new());
  if (EVP_DigestVerifyInit(ctx.get(), nullptr, nullptr, nullptr, k->get()) != 1 ||
      EVP_DigestVerify(ctx.get(), reinterpret_cast<const unsigned char*>(sig.data()), sig.size(),
                       reinterpret_cast<const unsigned char*>(data.data()), data.size()) != 1) {
    return absl::PermissionDeniedError("Ed25519 signature does not verify");
  }
  return absl::OkStatus();
}

}  // namespace fluxcal::tables
