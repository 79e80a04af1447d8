#include "pipeline/recording_archive.h"

#include <zlib.h>

#include <charconv>

#include "absl/strings/str_cat.h"
#include "fluxcal/v1/calibration.pb.h"

namespace fluxcal::pipeline {
namespace {

constexpr std::string_view kMagicV2 = "fluxcal.recording-archive.v2\n";

absl::Status CheckName(const std::string& name) {
  if (auto s = io::ValidateRecordingFileName(name); !s.ok()) {
    return absl::DataLossError(absl::StrCat("stored recording: ", s.message()));
  }
  return absl::OkStatus();
}

// The first stored format: records "name\nsize\nbytes", concatenated.
absl::StatusOr<io::RecordingFiles> DecodeV1(std::string_view in) {
  io::RecordingFiles files;
  size_t pos = 0;
  while (pos < in.size()) {
    const size_t a = in.find('\n', pos);
    const size_t b = a == std::string_view::npos ? a : in.find('\n', a + 1);
    if (b == std::string_view::npos) return absl::DataLossError("stored recording: corrupt archive header");
    std::string name(in.substr(pos, a - pos));
    if (auto s = CheckName(name); !s.ok()) return s;
    const std::string_view digits = in.substr(a + 1, b - a - 1);
    size_t size = 0;
    const auto [end, ec] = std::from_chars(digits.data(), digits.data() + digits.size(), size);
    if (ec != std::errc() || end != digits.data() + digits.size() || digits.empty()) {
      return absl::DataLossError("stored recording: corrupt archive size");
    }
    if (size > in.size() - (b + 1)) return absl::DataLossError("stored recording: truncated archive");
    if (!files.emplace(std::move(name), std::string(in.substr(b + 1, size))).second) {
      return absl::DataLossError("stored recording: duplicate file name");
    }
    pos = b + 1 + size;
  }
  return files;
}

}  // namespace

std::string EncodeRecordingArchive(const io::RecordingFiles& files) {
  v1::RecordingArchive a;
  for (const auto& [name, data] : files) {
    auto* f = a.add_files();
    f->set_name(name);
    f->set_data(data);
  }
  std::string out(kMagicV2);
  a.AppendToString(&out);
  return out;
}

absl::StatusOr<io::RecordingFiles> DecodeRecordingArchive(std::string_view bytes) {
  if (bytes.substr(0, kMagicV2.size()) != kMagicV2) return DecodeV1(bytes);
  v1::RecordingArchive a;
  const std::string_view body = bytes.substr(kMagicV2.size());
  if (!a.ParseFromArray(body.data(), static_cast<int>(body.size()))) {
    return absl::DataLossError("stored recording: corrupt archive");
  }
  io::RecordingFiles files;
  for (auto& f : *a.mutable_files()) {
    if (auto s = CheckName(f.name()); !s.ok()) return s;
    if (!files.emplace(f.name(), std::move(*f.mutable_data())).second) {
      return absl::DataLossError("stored recording: duplicate file name");
    }
  }
  return files;
}

absl::StatusOr<std::vector<uint8_t>> Deflate(std::string_view bytes) {
  uLongf zlen = compressBound(bytes.size());
  std::vector<uint8_t> z(zlen);
  if (compress2(z.data(), &zlen, reinterpret_cast<const Bytef*>(bytes.data()), bytes.size(), 6) != Z_OK) {
    return absl::InternalError("zlib: compression failed");
  }
  z.resize(zlen);
  return z;
}

absl::StatusOr<std::string> Inflate(const std::vector<uint8_t>& z, size_t max_bytes) {
  z_stream s{};
  if (inflateInit(&s) != Z_OK) return absl::InternalError("zlib: inflateInit failed");
  s.next_in = const_cast<Bytef*>(z.data());
  s.avail_in = static_cast<uInt>(z.size());
  std::string out;
  char buf[1 << 16];
  int rc = Z_OK;
  while (rc != Z_STREAM_END) {
    s.next_out = reinterpret_cast<Bytef*>(buf);
    s.avail_out = sizeof buf;
    rc = inflate(&s, Z_NO_FLUSH);
    if (rc != Z_OK && rc != Z_STREAM_END) {
      inflateEnd(&s);
      return absl::DataLossError("stored recording: zlib stream corrupt or truncated");
    }
    out.append(buf, sizeof buf - s.avail_out);
    if (out.size() > max_bytes) {
      inflateEnd(&s);
      return absl::DataLossError(absl::StrCat("stored recording: expands beyond ", max_bytes, " bytes"));
    }
    if (rc == Z_OK && s.avail_in == 0 && s.avail_out != 0) {
      inflateEnd(&s);
      return absl::DataLossError("stored recording: zlib stream truncated");
    }
  }
  inflateEnd(&s);
  return out;
}

}  // namespace fluxcal::pipeline
