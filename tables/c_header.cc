// The C header export format (docs/tables.md): the values as double,
// float or fixed-point arrays, the scalars as macros, the text fields as
// strings.
#include <cmath>
#include <cstdint>

#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "tables/internal_formats.h"
#include "tables/tables.h"

namespace fluxcal::tables::internal {
namespace {

std::string CString(const std::string& s) {
  return absl::StrCat("\"", absl::StrReplaceAll(OneLine(s), {{"\\", "\\\\"}, {"\"", "\\\""}}), "\"");
}

// A C literal of the element type: always with a '.' or exponent, and the
// 'f' suffix for float (a bare "0f" is not C). Float keeps 9 significant
// digits, enough to round-trip a binary32 (IEEE 754-2008, 5.12.2).
std::string CNum(double v, CType ct) {
  std::string s = ct == CType::kFloat ? absl::StrFormat("%.9g", static_cast<float>(v)) : Num(v);
  if (s.find_first_of(".eE") == std::string::npos) s += ".0";
  if (ct == CType::kFloat) s += "f";
  return s;
}

// The C element type of the value arrays.
const char* CElementType(CType ct) {
  switch (ct) {
    case CType::kFloat: return "float";
    case CType::kInt16: return "int16_t";
    case CType::kInt32: return "int32_t";
    case CType::kDouble: break;
  }
  return "double";
}

// An integer literal of a fixed-point array; the type's minimum is written
// as (-max - 1): "-2147483648" is the negation of a constant too large for
// int (C99 6.4.4.1).
std::string CInt(int64_t raw, int bits) {
  const int64_t lo = -(int64_t{1} << (bits - 1));
  return raw == lo ? absl::StrCat("(", lo + 1, " - 1)") : absl::StrCat(raw);
}

}  // namespace

absl::StatusOr<std::string> CHeader(const Table& t, CType ct, const std::vector<QuantityScale>& fixed) {
  const std::string g = Label(t, "TABLE_H_");
  const char* type = CElementType(ct);
  const int bits = FixedPointBits(ct);
  std::string s = absl::StrFormat("/* fluxcal %s table. Units: SI (A, N m, rpm, Wb, V, Ohm, degC).\n", TableTitle(t));
  for (const auto& [k, v] : TextFields(t)) s += absl::StrCat(" * ", k, ": ", OneLine(v), "\n");
  s += absl::StrCat(" * calibration_version: ", t.calibration_version, "\n");
  for (const auto& sc : Scalars(t)) {
    if (sc.name == "calibration_version") continue;
    s += absl::StrCat(" * ", sc.name, ": ", Num(sc.value), " ", sc.unit, " (", OneLine(sc.description), ")\n");
  }
  s += absl::StrCat(" * axis order: ", AxisOrder(t), ".\n");
  std::vector<std::string> flag_names;
  for (const auto& [name, v] : Flags(t)) flag_names.push_back(Label(t, name));
  s += absl::StrCat(" * Value arrays are ", type, bits > 0 ? " fixed point (below)" : "", "; ",
                    absl::StrJoin(flag_names, " / "), " are 0/1 per cell.\n");
  if (bits > 0) {
    // docs/tables.md, "Fixed point": one power-of-two LSB per quantity.
    s += absl::StrCat(" * Fixed point: physical = raw * LSB + offset, raw the ", type,
                      " value rounded to the nearest\n * integer (error at most LSB/2); <ARRAY>_LSB states each array's LSB:\n");
    for (const auto& q : fixed) {
      s += absl::StrFormat(" *   %s: LSB %s %s (2^%d), offset %s %s, range %s .. %s %s: %s\n", q.unit, Num(q.lsb),
                           q.unit, static_cast<int>(std::lround(std::log2(q.lsb))), Num(q.offset), q.unit,
                           Num(q.min_value), Num(q.max_value), q.unit, absl::StrJoin(q.arrays, ", "));
    }
  }
  s += " * payload_crc32 / payload_sha256: over the values as IEEE-754 binary64 (fluxcal docs/tables.md),\n"
       " * not over this file";
  if (ct == CType::kFloat) s += "; the float arrays hold those values rounded to binary32";
  if (bits > 0) s += absl::StrCat("; the ", type, " arrays hold them rounded to the nearest LSB");
  s += ". */\n";
  s += absl::StrFormat("#ifndef %s\n#define %s\n\n#include <stdint.h>\n\n", g, g);
  for (const auto& sc : Scalars(t)) {
    s += absl::StrFormat("#define %s %s\n", Label(t, sc.name),
                         sc.integer ? absl::StrCat(static_cast<long long>(sc.value)) : CNum(sc.value, ct));
  }
  s += "\n";
  for (const auto& [k, v] : TextFields(t)) {
    s += absl::StrFormat("static const char %s[] = %s;\n", CSymbol(t, k), CString(v));
  }
  s += "\n";
  auto arr = [&](const std::string& name, const std::vector<double>& v, const char* ty, bool flag) -> absl::Status {
    std::vector<std::string> lit(v.size());
    const QuantityScale* q = flag ? nullptr : ScaleOf(fixed, name);
    s += absl::StrFormat("#define %s_LEN %d\n", Label(t, name), v.size());
    if (bits > 0 && q != nullptr) {
      auto raw = Quantize(v, *q, absl::StrCat("table array '", name, "'"));
      if (!raw.ok()) return raw.status();
      for (size_t k = 0; k < v.size(); ++k) lit[k] = CInt((*raw)[k], bits);
      s += absl::StrFormat("#define %s_LSB %s\n", Label(t, name), CNum(q->lsb, CType::kDouble));
    } else {
      for (size_t k = 0; k < v.size(); ++k) lit[k] = flag ? (v[k] != 0 ? "1" : "0") : CNum(v[k], ct);
    }
    s += absl::StrFormat("static const %s %s[%d] = {\n", ty, CSymbol(t, name), v.size());
    for (size_t k = 0; k < v.size(); ++k) s += absl::StrCat("  ", lit[k], k + 1 < v.size() ? ",\n" : "\n");
    s += "};\n\n";
    return absl::OkStatus();
  };
  for (const auto& a : t.axes) {
    if (auto st = arr(a.name, a.values, type, false); !st.ok()) return st;
  }
  for (const auto& o : t.outputs) {
    if (auto st = arr(o.name, o.values, type, false); !st.ok()) return st;
  }
  for (const auto& [name, v] : Flags(t)) {
    if (auto st = arr(name, AsDoubles(*v), "uint8_t", true); !st.ok()) return st;
  }
  s += absl::StrFormat("static const uint32_t %s = 0x%08xu;\n", CSymbol(t, "payload_crc32"), t.crc32);
  s += absl::StrFormat("static const char %s[] = \"%s\";\n\n#endif\n",
                       CSymbol(t, "payload_sha256"), t.sha256);
  return s;
}

}  // namespace fluxcal::tables::internal
