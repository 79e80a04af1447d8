#include "server/limits.h"

#include <malloc.h>

#include <algorithm>

#include "absl/strings/str_cat.h"

namespace fluxcal::server {
namespace {

// A call that held this much is worth a malloc_trim when it ends: glibc
// keeps freed memory of its arenas for reuse, so without it the resident
// size of the server only ratchets up after large uploads.
constexpr int64_t kTrimAfterBytes = int64_t{16} << 20;

}  // namespace

absl::StatusOr<IdentityLimiter::Lease> IdentityLimiter::Acquire(const std::string& identity) {
  std::lock_guard<std::mutex> l(mu_);
  Usage& u = usage_[identity];
  if (u.streams >= limits_.max_streams) {
    return absl::ResourceExhaustedError(absl::StrCat("'", identity, "' has ", u.streams,
                                                     " calls open, the limit per identity (server flag "
                                                     "--max-streams-per-identity); retry when one ends"));
  }
  ++u.streams;
  Lease lease;
  lease.owner_ = this;
  lease.identity_ = identity;
  return lease;
}

IdentityLimiter::Usage IdentityLimiter::UsageOf(const std::string& identity) const {
  std::lock_guard<std::mutex> l(mu_);
  auto it = usage_.find(identity);
  return it == usage_.end() ? Usage{} : it->second;
}

absl::Status IdentityLimiter::Lease::Add(int64_t bytes) {
  if (owner_ == nullptr || bytes <= 0) return absl::OkStatus();
  std::lock_guard<std::mutex> l(owner_->mu_);
  Usage& u = owner_->usage_[identity_];
  if (u.bytes + bytes > owner_->limits_.max_inflight_bytes) {
    const int64_t held = u.bytes;
    // The call ends with this error: what it holds is given back now, in the
    // same step, so that another call of the identity crossing the limit a
    // moment later is not refused for bytes about to be freed.
    u.bytes -= bytes_;
    peak_bytes_ = std::max(peak_bytes_, bytes_);
    bytes_ = 0;
    return absl::ResourceExhaustedError(absl::StrCat(
        "'", identity_, "' holds ", held, " bytes of requests in its open calls; ", bytes,
        " more would pass the limit per identity of ", owner_->limits_.max_inflight_bytes,
        " bytes (server flag --max-inflight-bytes-per-identity); retry when its other calls end"));
  }
  u.bytes += bytes;
  bytes_ += bytes;
  return absl::OkStatus();
}

void IdentityLimiter::Lease::Release() {
  if (owner_ == nullptr) return;
  const int64_t held = std::max(peak_bytes_, bytes_);
  {
    std::lock_guard<std::mutex> l(owner_->mu_);
    auto it = owner_->usage_.find(identity_);
    if (it != owner_->usage_.end()) {
      it->second.bytes -= bytes_;
      if (--it->second.streams == 0) owner_->usage_.erase(it);
    }
  }
  owner_ = nullptr;
  bytes_ = 0;
  peak_bytes_ = 0;
  if (held >= kTrimAfterBytes) ::malloc_trim(0);
}

IdentityLimiter::Lease& IdentityLimiter::Lease::operator=(Lease&& o) noexcept {
  if (this != &o) {
    Release();
    owner_ = o.owner_;
    identity_ = std::move(o.identity_);
    bytes_ = o.bytes_;
    peak_bytes_ = o.peak_bytes_;
    o.owner_ = nullptr;
    o.bytes_ = 0;
    o.peak_bytes_ = 0;
  }
  return *this;
}

IdentityLimiter::Lease::~Lease() { Release(); }

void ReturnLargeBlocksWhenFreed() {
  // mallopt(3): setting M_MMAP_THRESHOLD turns off its dynamic adjustment.
  ::mallopt(M_MMAP_THRESHOLD, 128 * 1024);
}

}  // namespace fluxcal::server
