// Strict CSV reading for recording sets: a header line of known column names,
// then rows of numbers. Every error names file, line and field.
#ifndef FLUXCAL_IO_CSV_H_
#define FLUXCAL_IO_CSV_H_

#include <string>
#include <string_view>
#include <vector>

#include "absl/status/statusor.h"

namespace fluxcal::io {

struct CsvColumnSpec {
  std::string name;
  bool optional_cells = false;   // an empty cell is allowed (stored as NaN)
};

// Parsed numeric table; columns[c][row]. Empty optional cells are NaN.
struct CsvTable {
  std::vector<std::vector<double>> columns;
  size_t rows = 0;
};

// Parses `text` (contents of `display_path`) whose header must list exactly
// `spec` (in this order), followed by any of the `extension` columns (each
// at most once, in any order; docs/recording-format.md names the known
// ones). Rejects missing/unknown/repeated/reordered columns, wrong cell
// counts, non-numeric cells, NaN/inf (literal or overflowing). The table
// holds spec.size() + extension.size() columns, spec's then extension's; an
// extension column the header does not list is all NaN.
absl::StatusOr<CsvTable> ParseNumericCsv(std::string_view text,
                                         const std::string& display_path,
                                         const std::vector<CsvColumnSpec>& spec,
                                         const std::vector<CsvColumnSpec>& extension = {});

// `text` made safe to echo in a message, a log line or JSON: printable ASCII
// and well-formed UTF-8 are kept, every other byte becomes \xNN.
std::string Printable(std::string_view text);

// Reads a whole file. NotFound names the path.
absl::StatusOr<std::string> ReadFileToString(const std::string& path);

// Writes via a temporary file and rename, so a crash never leaves a partial
// file under the final name.
absl::Status WriteFileAtomically(const std::string& path, std::string_view contents);

}  // namespace fluxcal::io

#endif  // FLUXCAL_IO_CSV_H_
