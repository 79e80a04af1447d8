#include "io/sha256.h"

#include <openssl/evp.h>

namespace fluxcal::io {

std::string Sha256Hex(std::string_view data) {
  unsigned char md[EVP_MAX_MD_SIZE];
  unsigned int n = 0;
  EVP_Digest(data.data(), data.size(), md, &n, EVP_sha256(), nullptr);
  static constexpr char kHex[] = "0123456789abcdef";
  std::string out(2 * n, '0');
  for (unsigned int k = 0; k < n; ++k) {
    out[2 * k] = kHex[md[k] >> 4];
    out[2 * k + 1] = kHex[md[k] & 15];
  }
  return out;
}

}  // namespace fluxcal::io
