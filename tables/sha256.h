// SHA-256 (FIPS 180-4) through OpenSSL's libcrypto (EVP), checked against
// the NIST test vectors in tests/tables.
#ifndef FLUXCAL_TABLES_SHA256_H_
#define FLUXCAL_TABLES_SHA256_H_

#include <string>
#include <string_view>

namespace fluxcal::tables {

// Lower-case hex digest of `data`.
std::string Sha256Hex(std::string_view data);

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TABLES_SHA256_H_
