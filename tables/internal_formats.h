// The export formats' writers and the helpers they share (internal to
// tables/, not installed). Export (export.cc) checks the table and calls
// one writer; A2L has its own (tables/a2l.h).
#ifndef FLUXCAL_TABLES_INTERNAL_FORMATS_H_
#define FLUXCAL_TABLES_INTERNAL_FORMATS_H_

#include <cstdint>
#include <string>
#include <vector>

#include "absl/status/statusor.h"
#include "tables/tables.h"

namespace fluxcal::tables::internal {

// A value as printf's "%.17g" writes it (export.cc).
std::string Num(double v);
// Num(v) appended to *out, without the temporary string (the writers'
// per-value loops: a fw table's CDFX holds ~10^4 values).
void AppendNum(std::string* out, double v);
// The payload CRC-32 as 8 hex digits.
std::string Crc(const Table& t);
// The flag arrays as doubles, for the writers that treat them as tables.
std::vector<double> AsDoubles(const std::vector<uint8_t>& v);

// What the table is, for the first line of every file: the kind, "envelope
// (generating)" for the generating envelope.
inline std::string TableTitle(const Table& t) {
  return t.kind == "envelope" && t.envelope_generating ? "envelope (generating)" : t.kind;
}

std::string Csv(const Table& t);    // csv_json.cc
std::string Json(const Table& t);   // csv_json.cc
// C header (c_header.cc); `fixed`: QuantityScales(t, ct). OutOfRange from
// Quantize.
absl::StatusOr<std::string> CHeader(const Table& t, CType ct, const std::vector<QuantityScale>& fixed);
std::string Cdfx(const Table& t);   // cdfx.cc: ASAM CDF 2.0
std::string Dcm(const Table& t);    // dcm.cc: DAMOS DCM 2.0

}  // namespace fluxcal::tables::internal

#endif  // FLUXCAL_TABLES_INTERNAL_FORMATS_H_
