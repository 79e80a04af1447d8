#include "io/csv.h"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <system_error>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"

namespace fluxcal::io {
namespace {

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

// A cell or header echoed in a message: at most 40 bytes, escaped.
std::string Shorten(std::string_view s) {
  if (s.size() <= 40) return Printable(s);
  return absl::StrCat(Printable(s.substr(0, 37)), "...");
}

}  // namespace

absl::StatusOr<std::string> ReadFileToString(const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (f == nullptr) {
    return absl::NotFoundError(absl::StrCat(path, ": file not found or not readable"));
  }
  std::string out;
  char buf[1 << 16];
  size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) out.append(buf, n);
  const bool err = std::ferror(f);
  std::fclose(f);
  if (err) return absl::DataLossError(absl::StrCat(path, ": read error"));
  return out;
}

absl::Status WriteFileAtomically(const std::string& path, std::string_view contents) {
  const std::string tmp = path + ".tmp";
  std::FILE* f = std::fopen(tmp.c_str(), "wb");
  if (f == nullptr) {
    return absl::PermissionDeniedError(absl::StrCat(path, ": cannot open for writing"));
  }
  const bool ok = std::fwrite(contents.data(), 1, contents.size(), f) == contents.size();
  const bool flushed = std::fflush(f) == 0;
  std::fclose(f);
  if (!ok || !flushed || std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    return absl::DataLossError(absl::StrCat(path, ": write failed"));
  }
  return absl::OkStatus();
}

absl::StatusOr<CsvTable> ParseNumericCsv(std::string_view text,
                                         const std::string& display_path,
                                         const std::vector<CsvColumnSpec>& spec,
                                         const std::vector<CsvColumnSpec>& extension) {
  CsvTable table;
  table.columns.resize(spec.size() + extension.size());
  size_t pos = 0;
  size_t line_no = 0;
  bool header_seen = false;
  // The file's columns in header order: each an index into `columns`
  // (spec's, then extension's).
  std::vector<size_t> column_of;
  auto spec_of = [&](size_t column) -> const CsvColumnSpec& {
    return column < spec.size() ? spec[column] : extension[column - spec.size()];
  };
  // Reserve from a cheap line-count estimate to keep parsing allocation-free.
  const size_t approx_rows = static_cast<size_t>(std::count(text.begin(), text.end(), '\n'));
  for (auto& c : table.columns) c.reserve(approx_rows);

  while (pos < text.size()) {
    size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) eol = text.size();
    std::string_view line = text.substr(pos, eol - pos);
    pos = eol + 1;
    ++line_no;
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (!header_seen) {
      header_seen = true;
      std::vector<std::string_view> names;
      size_t s = 0;
      while (true) {
        size_t comma = line.find(',', s);
        names.push_back(Trim(line.substr(s, comma == std::string_view::npos ? line.npos : comma - s)));
        if (comma == std::string_view::npos) break;
        s = comma + 1;
      }
      for (size_t c = 0; c < spec.size(); ++c) {
        if (c >= names.size()) {
          return absl::InvalidArgumentError(absl::StrCat(
              display_path, ":1: field '", spec[c].name, "': missing column in header"));
        }
        if (names[c] != spec[c].name) {
          bool elsewhere = false;
          for (auto n : names) elsewhere |= (n == spec[c].name);
          return absl::InvalidArgumentError(absl::StrCat(
              display_path, ":1: field '", spec[c].name, "': ",
              elsewhere ? "column out of order" : "missing column", " (header has '",
              Shorten(names[c]), "' at column ", c + 1, ")"));
        }
        column_of.push_back(c);
      }
      for (size_t c = spec.size(); c < names.size(); ++c) {
        size_t e = 0;
        while (e < extension.size() && names[c] != extension[e].name) ++e;
        if (e == extension.size()) {
          std::string known;
          for (const auto& x : extension) absl::StrAppend(&known, known.empty() ? "" : ", ", x.name);
          return absl::InvalidArgumentError(absl::StrCat(
              display_path, ":1: field '", Shorten(names[c]),
              "': unknown column (format fluxcal.recording.v1 expects ", spec.size(), " columns",
              known.empty() ? std::string() : absl::StrCat(", then any of ", known), ")"));
        }
        if (std::find(column_of.begin(), column_of.end(), spec.size() + e) != column_of.end()) {
          return absl::InvalidArgumentError(absl::StrCat(display_path, ":1: field '", extension[e].name,
                                                         "': column repeated (at column ", c + 1, ")"));
        }
        column_of.push_back(spec.size() + e);
      }
      continue;
    }
    if (Trim(line).empty()) {
      // Only a trailing empty line is tolerated.
      if (pos >= text.size()) break;
      return absl::InvalidArgumentError(
          absl::StrCat(display_path, ":", line_no, ": field '", spec[0].name, "': empty line"));
    }
    const size_t cells = column_of.size();
    size_t s = 0;
    for (size_t c = 0; c < cells; ++c) {
      const CsvColumnSpec& col = spec_of(column_of[c]);
      size_t comma = line.find(',', s);
      const bool last = (c + 1 == cells);
      if (!last && comma == std::string_view::npos) {
        return absl::InvalidArgumentError(absl::StrCat(
            display_path, ":", line_no, ": field '", spec_of(column_of[c + 1]).name,
            "': missing cell (row has ", c + 1, " of ", cells, " cells)"));
      }
      if (last && comma != std::string_view::npos) {
        return absl::InvalidArgumentError(absl::StrCat(
            display_path, ":", line_no, ": field '", col.name,
            "': too many cells (expected ", cells, ")"));
      }
      std::string_view cell = Trim(line.substr(s, last ? line.npos : comma - s));
      s = comma + 1;
      double v = 0.0;
      if (cell.empty()) {
        if (!col.optional_cells) {
          return absl::InvalidArgumentError(absl::StrCat(
              display_path, ":", line_no, ": field '", col.name, "': empty cell"));
        }
        v = std::numeric_limits<double>::quiet_NaN();
      } else {
        const char* b = cell.data();
        const char* e = cell.data() + cell.size();
        if (*b == '+') ++b;  // from_chars rejects a leading '+'
        auto [ptr, ec] = std::from_chars(b, e, v);
        if (ec == std::errc::result_out_of_range) {
          return absl::InvalidArgumentError(absl::StrCat(
              display_path, ":", line_no, ": field '", col.name,
              "': number out of range, got '", Shorten(cell), "'"));
        }
        if (ec != std::errc() || ptr != e) {
          return absl::InvalidArgumentError(absl::StrCat(
              display_path, ":", line_no, ": field '", col.name,
              "': expected a number, got '", Shorten(cell), "'"));
        }
        if (!std::isfinite(v)) {
          return absl::InvalidArgumentError(absl::StrCat(
              display_path, ":", line_no, ": field '", col.name,
              "': expected a finite number, got '", Shorten(cell), "'"));
        }
      }
      table.columns[column_of[c]].push_back(v);
    }
    // Extension columns the header does not list: every cell absent.
    for (size_t e = 0; e < extension.size(); ++e) {
      auto& column = table.columns[spec.size() + e];
      if (column.size() == table.rows) column.push_back(std::numeric_limits<double>::quiet_NaN());
    }
    ++table.rows;
  }
  if (!header_seen) {
    return absl::InvalidArgumentError(
        absl::StrCat(display_path, ":1: field '", spec[0].name, "': empty file, no header"));
  }
  return table;
}

std::string Printable(std::string_view text) {
  // Keeps printable ASCII and well-formed UTF-8 multi-byte sequences (RFC
  // 3629 ranges, no overlongs or surrogates); every other byte becomes \xNN,
  // so that messages are valid UTF-8 for JSON and cannot carry control
  // characters into logs or metadata.
  std::string out;
  out.reserve(text.size());
  const auto* s = reinterpret_cast<const unsigned char*>(text.data());
  const size_t n = text.size();
  for (size_t i = 0; i < n;) {
    const unsigned char c = s[i];
    if (c >= 0x20 && c < 0x7f) {
      out.push_back(static_cast<char>(c));
      ++i;
      continue;
    }
    size_t len = 0;
    unsigned char lo = 0x80, hi = 0xbf;
    if (c >= 0xc2 && c <= 0xdf) len = 2;
    else if (c >= 0xe0 && c <= 0xef) { len = 3; if (c == 0xe0) lo = 0xa0; if (c == 0xed) hi = 0x9f; }
    else if (c >= 0xf0 && c <= 0xf4) { len = 4; if (c == 0xf0) lo = 0x90; if (c == 0xf4) hi = 0x8f; }
    bool ok = len > 0 && i + len <= n;
    for (size_t k = 1; ok && k < len; ++k) {
      const unsigned char b = s[i + k];
      ok = k == 1 ? (b >= lo && b <= hi) : (b >= 0x80 && b <= 0xbf);
    }
    if (ok) {
      out.append(text.substr(i, len));
      i += len;
    } else {
      absl::StrAppend(&out, absl::StrFormat("\\x%02x", c));
      ++i;
    }
  }
  return out;
}

}  // namespace fluxcal::io
