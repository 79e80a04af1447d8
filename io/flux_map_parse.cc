// Reading a flux map's CSV: the header's columns found by their accepted
// spellings, each row's four numbers, the nodes assembled into a full
// grid; every refusal names the file, line and field. The numbers are put
// into fluxcal's convention and checked afterwards (flux_map_conform.cc).
#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <set>
#include <system_error>
#include <vector>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "io/csv.h"
#include "io/flux_map.h"
#include "io/flux_map_internal.h"
#include "io/plausibility.h"

namespace fluxcal::io {
namespace internal {

absl::Status FieldError(const std::string& path, size_t line, std::string_view field, const std::string& what) {
  return absl::InvalidArgumentError(absl::StrCat(path, ":", line, ": field '", Shorten(field), "': ", what));
}

// A cell or header echoed in a message: at most 40 bytes, escaped.
std::string Shorten(std::string_view s) {
  if (s.size() <= 40) return Printable(s);
  return absl::StrCat(Printable(s.substr(0, 37)), "...");
}

std::string Num(double x) { return absl::StrFormat("%.10g", x); }

}  // namespace internal

namespace {

using internal::FieldError;
using internal::kId;
using internal::kIq;
using internal::kPsiD;
using internal::kPsiQ;
using internal::kRoles;
using internal::Node;
using internal::Nodes;
using internal::Num;
using internal::Role;
using internal::Shorten;

// Spellings per role (matched case-insensitively), raw and symmetrised
// flux pairs.
const std::vector<std::string>& Spellings(Role r, FluxMapColumns columns) {
  static const std::vector<std::string> kIdNames = {"id_A", "id", "i_d", "i_d_A"};
  static const std::vector<std::string> kIqNames = {"iq_A", "iq", "i_q", "i_q_A"};
  static const std::vector<std::string> kPsiDRaw = {"psi_d_Vs", "psi_d_Wb", "psi_d_mVs", "psi_d_mWb",
                                                    "psi_d",    "psid",     "Fd"};
  static const std::vector<std::string> kPsiQRaw = {"psi_q_Vs", "psi_q_Wb", "psi_q_mVs", "psi_q_mWb",
                                                    "psi_q",    "psiq",     "Fq"};
  static const std::vector<std::string> kPsiDSym = {"psi_d_sym_Vs", "psi_d_sym_Wb", "psi_d_sym_mVs",
                                                    "psi_d_sym_mWb", "psi_d_sym"};
  static const std::vector<std::string> kPsiQSym = {"psi_q_sym_Vs", "psi_q_sym_Wb", "psi_q_sym_mVs",
                                                    "psi_q_sym_mWb", "psi_q_sym"};
  const bool sym = columns == FluxMapColumns::kSymmetrised;
  switch (r) {
    case kId: return kIdNames;
    case kIq: return kIqNames;
    case kPsiD: return sym ? kPsiDSym : kPsiDRaw;
    default: return sym ? kPsiQSym : kPsiQRaw;
  }
}

// The canonical name of a role in messages about a column that is absent.
const char* RoleName(Role r, FluxMapColumns columns) {
  const bool sym = columns == FluxMapColumns::kSymmetrised;
  switch (r) {
    case kId: return "id";
    case kIq: return "iq";
    case kPsiD: return sym ? "psi_d_sym" : "psi_d";
    default: return sym ? "psi_q_sym" : "psi_q";
  }
}

std::string_view Trim(std::string_view s) {
  while (!s.empty() && (s.front() == ' ' || s.front() == '\t')) s.remove_prefix(1);
  while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r')) s.remove_suffix(1);
  return s;
}

std::vector<std::string_view> SplitCells(std::string_view line) {
  std::vector<std::string_view> cells;
  size_t s = 0;
  while (true) {
    const size_t comma = line.find(',', s);
    cells.push_back(Trim(line.substr(s, comma == std::string_view::npos ? line.npos : comma - s)));
    if (comma == std::string_view::npos) break;
    s = comma + 1;
  }
  return cells;
}

// The header line: which column holds each role, the file's names for them.
struct Columns {
  size_t line = 1;
  std::vector<std::string> header;
  int col[kRoles] = {-1, -1, -1, -1};
};

// Finds each role's column in the header `line` (line `line_no`); refuses
// a role named twice or not at all.
absl::Status ReadHeader(std::string_view line, size_t line_no, const std::string& path,
                        const FluxMapReadOptions& options, Columns* cols) {
  auto error = [&](size_t line, std::string_view field, const std::string& what) {
    return FieldError(path, line, field, what);
  };
  std::vector<std::string>& header = cols->header;
  int* col = cols->col;
  cols->line = line_no;
  for (auto name : SplitCells(line)) {
    if (name.size() >= 2 && name.front() == '"' && name.back() == '"') name = name.substr(1, name.size() - 2);
    header.emplace_back(name);
  }
  for (int r = 0; r < kRoles; ++r) {
    const auto& names = Spellings(static_cast<Role>(r), options.columns);
    for (size_t c = 0; c < header.size(); ++c) {
      const std::string lower = absl::AsciiStrToLower(header[c]);
      if (std::none_of(names.begin(), names.end(),
                       [&](const std::string& n) { return absl::AsciiStrToLower(n) == lower; })) {
        continue;
      }
      if (col[r] >= 0) {
        return error(line_no, header[c],
                     absl::StrCat("ambiguous: columns ", col[r] + 1, " ('", Shorten(header[col[r]]), "') and ",
                                  c + 1, " both name ", RoleName(static_cast<Role>(r), options.columns)));
      }
      col[r] = static_cast<int>(c);
    }
  }
  for (int r = 0; r < kRoles; ++r) {
    if (col[r] >= 0) continue;
    std::vector<std::string> shown;
    for (size_t c = 0; c < header.size() && c < 12; ++c) shown.push_back(Shorten(header[c]));
    if (header.size() > 12) shown.push_back(absl::StrCat("... (", header.size(), " columns)"));
    std::string what = absl::StrCat("missing column (accepted, any case: ",
                                    absl::StrJoin(Spellings(static_cast<Role>(r), options.columns), ", "),
                                    "; header has ", absl::StrJoin(shown, ", "), ")");
    if (header.size() == 1 && (line.find(';') != line.npos || line.find('\t') != line.npos)) {
      absl::StrAppend(&what, "; expected comma-separated values");
    }
    return error(line_no, RoleName(static_cast<Role>(r), options.columns), what);
  }
  return absl::OkStatus();
}

// One data row (line `line_no`): its four numbers, a node not seen before.
absl::Status ReadRow(std::string_view line, size_t line_no, const std::string& path, const Columns& cols,
                     Nodes* nodes) {
  auto error = [&](size_t line, std::string_view field, const std::string& what) {
    return FieldError(path, line, field, what);
  };
  const std::vector<std::string>& header = cols.header;
  const int* col = cols.col;
  const auto cells = SplitCells(line);
  if (cells.size() != header.size()) {
    const size_t c = std::min(cells.size(), header.size() - 1);
    return error(line_no, header[c],
                 absl::StrCat(cells.size() < header.size() ? "missing cell" : "too many cells", " (row has ",
                              cells.size(), ", header ", header.size(), ")"));
  }
  double v[kRoles];
  for (int r = 0; r < kRoles; ++r) {
    const std::string_view cell = cells[col[r]];
    const std::string& field = header[col[r]];
    if (cell.empty()) return error(line_no, field, "empty cell");
    const char* b = cell.data();
    const char* e = cell.data() + cell.size();
    if (*b == '+') ++b;   // from_chars rejects a leading '+'
    auto [ptr, ec] = std::from_chars(b, e, v[r]);
    if (ec == std::errc::result_out_of_range) {
      return error(line_no, field, absl::StrCat("number out of range, got '", Shorten(cell), "'"));
    }
    if (ec != std::errc() || ptr != e) {
      return error(line_no, field, absl::StrCat("expected a number, got '", Shorten(cell), "'"));
    }
    if (!std::isfinite(v[r])) {
      return error(line_no, field, absl::StrCat("expected a finite number, got '", Shorten(cell), "'"));
    }
  }
  // -0 + 0 = +0: "-0" and "0" are one axis value.
  const std::pair<double, double> key{v[kId] + 0.0, v[kIq] + 0.0};
  auto [it, inserted] = nodes->emplace(key, Node{v[kPsiD], v[kPsiQ], line_no});
  if (!inserted) {
    return error(line_no, header[col[kIq]],
                 absl::StrCat("duplicate node (id = ", Num(key.first), " A, iq = ", Num(key.second),
                              " A), first on line ", it->second.line));
  }
  return absl::OkStatus();
}

// The nodes as a grid over their distinct id and iq values; refuses a grid
// with a node missing, pointing at the nearest node of its id row.
absl::StatusOr<FluxMap> Grid(const Nodes& nodes, const std::string& path, const Columns& cols) {
  auto error = [&](size_t line, std::string_view field, const std::string& what) {
    return FieldError(path, line, field, what);
  };
  const std::vector<std::string>& header = cols.header;
  const int* col = cols.col;
  FluxMap map;
  map.source = path;
  std::set<double> ids, iqs;
  for (const auto& [key, node] : nodes) {
    ids.insert(key.first);
    iqs.insert(key.second);
  }
  map.id_a.assign(ids.begin(), ids.end());
  map.iq_a.assign(iqs.begin(), iqs.end());
  const size_t ni = map.id_a.size(), nq = map.iq_a.size();
  map.psi_d_wb.assign(ni, std::vector<double>(nq));
  map.psi_q_wb.assign(ni, std::vector<double>(nq));
  for (size_t i = 0; i < ni; ++i) {
    for (size_t j = 0; j < nq; ++j) {
      auto it = nodes.find({map.id_a[i], map.iq_a[j]});
      if (it != nodes.end()) {
        map.psi_d_wb[i][j] = it->second.psi_d_wb;
        map.psi_q_wb[i][j] = it->second.psi_q_wb;
        continue;
      }
      // Point at the nearest node of the same id row: where a map written
      // id-major lost its line. Every id value has at least one node.
      size_t best_line = 0;
      double best_iq = 0;
      for (size_t d = 1; d < nq && best_line == 0; ++d) {
        for (const size_t jj : {j - d, j + d}) {   // j - d wraps to a huge index when d > j
          if (jj >= nq) continue;
          if (auto nb = nodes.find({map.id_a[i], map.iq_a[jj]}); nb != nodes.end()) {
            best_line = nb->second.line;
            best_iq = map.iq_a[jj];
            break;
          }
        }
      }
      return error(best_line, header[col[kIq]],
                   absl::StrCat("missing node (id = ", Num(map.id_a[i]), " A, iq = ", Num(map.iq_a[j]),
                                " A): the map is not a full grid (", ni, " id values x ", nq, " iq values need ",
                                ni * nq, " nodes, the file has ", nodes.size(),
                                "); nearest node of this id row: iq = ", Num(best_iq), " A on line ", best_line));
    }
  }
  return map;
}

}  // namespace

absl::StatusOr<FluxMap> ParseFluxMapCsv(std::string_view text, const std::string& path,
                                        const FluxMapReadOptions& options) {
  auto error = [&](size_t line, std::string_view field, const std::string& what) {
    return FieldError(path, line, field, what);
  };
  if (text.size() > kMaxFluxMapBytes) {
    return error(1, "(file)", absl::StrCat("file is ", text.size(), " bytes, more than the ",
                                           kMaxFluxMapBytes >> 20, " MiB a flux map may have"));
  }
  if (text.substr(0, 3) == "\xEF\xBB\xBF") text.remove_prefix(3);   // UTF-8 BOM (spreadsheet exports)

  size_t pos = 0, line_no = 0;
  Columns c;
  bool header_seen = false;
  Nodes nodes;
  size_t rows = 0;
  while (pos < text.size()) {
    size_t eol = text.find('\n', pos);
    if (eol == std::string_view::npos) eol = text.size();
    const std::string_view line = Trim(text.substr(pos, eol - pos));
    pos = eol + 1;
    ++line_no;
    if (!header_seen) {
      if (line.empty() || line.front() == '#') continue;   // preamble
      header_seen = true;
      if (absl::Status s = ReadHeader(line, line_no, path, options, &c); !s.ok()) return s;
      continue;
    }
    if (line.empty()) {
      // Only trailing empty lines are tolerated.
      if (text.substr(std::min(pos, text.size())).find_first_not_of("\r\n \t") == std::string_view::npos) break;
      return error(line_no, c.header[c.col[kId]], "empty line");
    }
    if (++rows > kMaxFluxMapRows) {
      return error(line_no, c.header[c.col[kId]],
                   absl::StrCat("more than ", kMaxFluxMapRows, " rows; a flux map is a grid of at most 1000 x 1000"));
    }
    if (absl::Status s = ReadRow(line, line_no, path, c, &nodes); !s.ok()) return s;
  }
  if (!header_seen) return error(1, "id", "empty file, no header");
  if (nodes.empty()) return error(line_no, c.header[c.col[kId]], "no data rows after the header");
  auto map = Grid(nodes, path, c);
  if (!map.ok()) return map.status();
  internal::Header h;
  h.path = path;
  h.line = c.line;
  for (int r = 0; r < kRoles; ++r) h.col[r] = c.header[c.col[r]];
  return internal::Conform(*map, nodes, h, options.convention);
}

absl::StatusOr<FluxMap> ReadFluxMapCsv(const std::string& path, const FluxMapReadOptions& options) {
  std::error_code ec;
  const auto bytes = std::filesystem::file_size(path, ec);
  if (!ec && bytes > kMaxFluxMapBytes) {
    return absl::InvalidArgumentError(absl::StrCat(path, ":1: field '(file)': file is ", bytes,
                                                   " bytes, more than the ", kMaxFluxMapBytes >> 20,
                                                   " MiB a flux map may have"));
  }
  auto text = ReadFileToString(path);
  if (!text.ok()) return text.status();
  return ParseFluxMapCsv(*text, path, options);
}

}  // namespace fluxcal::io
