// SHA-256 (FIPS 180-4) through OpenSSL's libcrypto (EVP), checked against
// the NIST test vectors in tests/tables. One home for every SHA-256 in
// fluxcal: table checksums, signatures, the calibration hash chain.
#ifndef FLUXCAL_IO_SHA256_H_
#define FLUXCAL_IO_SHA256_H_

#include <string>
#include <string_view>

namespace fluxcal::io {

// Lower-case hex digest of `data`.
std::string Sha256Hex(std::string_view data);

}  // namespace fluxcal::io

#endif  // FLUXCAL_IO_SHA256_H_
