// Per-identity limits of the service: how many calls one identity may have
// open at once, and how many request bytes its open calls may hold. One
// credential (a station's token, a leaked one) can then take at most
// max_inflight_bytes of the server's memory for request data, however many
// streams it opens; the next stream or message past a limit ends
// RESOURCE_EXHAUSTED naming the limit, and what it held is freed.
//
// In open mode every caller is the one identity "local".
#ifndef FLUXCAL_SERVER_LIMITS_H_
#define FLUXCAL_SERVER_LIMITS_H_

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "absl/status/status.h"
#include "absl/status/statusor.h"

namespace fluxcal::server {

// The largest message the service reads (grpc max receive size). The
// largest legitimate request is a QueryFlux of 100 000 points (about 2 MB:
// two tagged doubles and a length, 20 bytes a point); recording chunks
// carry 1 MiB of data (`fluxcal eol` sends 1 MiB), so 4 MiB leaves room
// for both. Before a call is
// authenticated no message is read at all (server/auth.h,
// MakeAuthProcessor), except on --insecure listeners (docs/security.md).
inline constexpr int kMaxMessageBytes = 4 << 20;

struct IdentityLimits {
  int max_streams = 16;                          // open calls per identity
  int64_t max_inflight_bytes = int64_t{512} << 20;   // request bytes held by them
};

class IdentityLimiter {
 public:
  explicit IdentityLimiter(IdentityLimits limits = {}) : limits_(limits) {}
  const IdentityLimits& limits() const { return limits_; }

  // One open call of an identity. Move-only; the destructor gives back its
  // stream and bytes, and after a call that held more than 16 MiB returns
  // freed heap to the system (glibc malloc_trim), so the server's resident
  // memory falls back after a burst of large uploads.
  class Lease {
   public:
    Lease() = default;
    Lease(Lease&& o) noexcept { *this = std::move(o); }
    Lease& operator=(Lease&& o) noexcept;
    ~Lease();
    // Counts `bytes` more request data held by this call; RESOURCE_EXHAUSTED
    // when the identity would pass max_inflight_bytes. The call is to end
    // then: its bytes are given back at once (its stream at destruction).
    absl::Status Add(int64_t bytes);
    int64_t bytes() const { return bytes_; }

   private:
    friend class IdentityLimiter;
    void Release();
    IdentityLimiter* owner_ = nullptr;
    std::string identity_;
    int64_t bytes_ = 0;
    int64_t peak_bytes_ = 0;   // held before a refusal gave them back
  };

  // A new open call of `identity`; RESOURCE_EXHAUSTED when it has
  // max_streams open already.
  absl::StatusOr<Lease> Acquire(const std::string& identity);

  struct Usage {
    int streams = 0;
    int64_t bytes = 0;
  };
  Usage UsageOf(const std::string& identity) const;

 private:
  IdentityLimits limits_;
  mutable std::mutex mu_;
  std::map<std::string, Usage> usage_;
};

// Makes glibc serve every block of 128 KiB or more (recording chunks, the
// files assembled from them, parsed columns) by its own mmap and give it
// back to the system when freed. glibc's default raises that threshold
// after each large free (up to 32 MiB), after which such blocks come from
// the heap and stay with the process: the resident size of a server then
// only ratchets up after bursts of uploads. Process-wide; StartServer
// calls it.
void ReturnLargeBlocksWhenFreed();

}  // namespace fluxcal::server

#endif  // FLUXCAL_SERVER_LIMITS_H_
