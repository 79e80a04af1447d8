#include "pipeline/ingest_stream.h"

#include <cstring>

#include "absl/strings/str_cat.h"
#include "io/sha256.h"

namespace fluxcal::pipeline {
namespace {

// Big-endian fixed-width integers and IEEE-754 binary64 (the layout of
// Python's struct.pack(">I"), ">Q" and ">d").
void PutU32(std::string* out, uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) out->push_back(static_cast<char>((v >> s) & 0xff));
}
void PutU64(std::string* out, uint64_t v) {
  for (int s = 56; s >= 0; s -= 8) out->push_back(static_cast<char>((v >> s) & 0xff));
}
void PutF64(std::string* out, double d) {
  // Zero as +0: SQLite keeps a whole-number REAL as an integer, so -0.0
  // comes back as +0.0; the digest is over values, not their sign of zero.
  if (d == 0) d = 0.0;
  uint64_t bits = 0;
  static_assert(sizeof bits == sizeof d);
  std::memcpy(&bits, &d, sizeof bits);
  PutU64(out, bits);
}

}  // namespace

std::string HfPointsSha256(const std::vector<IdentifiedPoint>& points) {
  std::string buf = "fluxcal.hf-points.v1\n";
  buf.reserve(buf.size() + points.size() * 120);
  for (const auto& p : points) {
    PutU32(&buf, static_cast<uint32_t>(p.point_id.size()));
    buf += p.point_id;
    for (double v : {p.id_a, p.iq_a, p.speed_rpm, p.ld_h, p.lq_h}) PutF64(&buf, v);
    buf.push_back(p.ldq_h ? 1 : 0);
    if (p.ldq_h) PutF64(&buf, *p.ldq_h);
    for (double v : {p.ld_h_std, p.lq_h_std, p.ldq_h_std, p.temperature_c}) PutF64(&buf, v);
    buf.push_back(p.reliable ? 1 : 0);
    // Appended only where stated, so that a point without it digests as
    // before the field existed (an idempotency key keeps its meaning).
    if (p.hf_flux_radius_wb) {
      buf.push_back('r');
      PutF64(&buf, *p.hf_flux_radius_wb);
    }
  }
  return io::Sha256Hex(buf);
}

std::string RecordingFilesSha256(const io::RecordingFiles& files) {
  std::string buf = "fluxcal.recording-files.v1\n";
  buf.reserve(buf.size() + static_cast<size_t>(RecordingFilesBytes(files)) + files.size() * 64);
  for (const auto& [name, data] : files) {
    PutU32(&buf, static_cast<uint32_t>(name.size()));
    buf += name;
    PutU64(&buf, data.size());
    buf += data;
  }
  return io::Sha256Hex(buf);
}

int64_t RecordingFilesBytes(const io::RecordingFiles& files) {
  int64_t n = 0;
  for (const auto& [name, data] : files) n += static_cast<int64_t>(data.size());
  return n;
}

absl::Status CheckStreamEnd(const StreamTotals& declared, const StreamTotals& received, const std::string& field,
                            const std::string& what) {
  auto differs = [&](const char* name, const std::string& d, const std::string& r, const std::string& unit) {
    return absl::InvalidArgumentError(absl::StrCat(field, ".", name, ": the stream declares ", d, unit,
                                                   ", the service received ", r, unit,
                                                   " (a message was lost, cut or failed to parse); nothing stored"));
  };
  if (declared.messages != received.messages) {
    return differs("messages", absl::StrCat(declared.messages), absl::StrCat(received.messages), " messages");
  }
  if (declared.count != received.count) {
    return differs("count", absl::StrCat(declared.count), absl::StrCat(received.count), " " + what);
  }
  if (declared.bytes != received.bytes) {
    return differs("bytes", absl::StrCat(declared.bytes), absl::StrCat(received.bytes), " bytes");
  }
  if (declared.sha256 != received.sha256) {
    return differs("sha256", declared.sha256, received.sha256, "");
  }
  return absl::OkStatus();
}

absl::Status CheckStored(const StreamTotals& sent, const StreamTotals& stored, const std::string& what) {
  constexpr char kNotSent[] = ": what the service stored is not what this client sent";
  if (sent.count != stored.count) {
    return absl::DataLossError(
        absl::StrCat("the service stored ", stored.count, " ", what, ", this client sent ", sent.count, " ", what, kNotSent));
  }
  if (sent.bytes != stored.bytes) {
    return absl::DataLossError(
        absl::StrCat("the service stored ", stored.bytes, " bytes, this client sent ", sent.bytes, kNotSent));
  }
  if (sent.sha256 != stored.sha256) {
    return absl::DataLossError(absl::StrCat(
        "SHA-256 of the ", what, ": the service's over what it stored is ",
        stored.sha256.empty() ? "missing (a service without stream digests)" : stored.sha256,
        ", this client's over what it sent is ", sent.sha256, kNotSent));
  }
  return absl::OkStatus();
}

absl::StatusOr<RunDigest> DigestOfIngest(storage::Store& store, int64_t run_id, bool replayed,
                                         const std::vector<IdentifiedPoint>& points) {
  if (!replayed) return RunDigest{static_cast<int64_t>(points.size()), HfPointsSha256(points)};
  auto stored = store.RunPoints(run_id);
  if (!stored.ok()) return stored.status();
  return RunDigest{static_cast<int64_t>(stored->size()), HfPointsSha256(*stored)};
}

}  // namespace fluxcal::pipeline
