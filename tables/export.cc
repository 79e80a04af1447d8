// Export (tables/tables.h): the table checked and written in one format,
// and what every format shares: the payload and its checksums, labels,
// units, scalars, text fields and flags, the format and C type names.
#include <zlib.h>

#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_replace.h"
#include "io/sha256.h"
#include "tables/a2l.h"
#include "tables/internal_formats.h"
#include "tables/tables.h"

namespace fluxcal::tables {
namespace internal {

namespace {

// "%.17g" of a finite double by exact integer arithmetic, where it fits:
// |v| in [1e-10, 1e16), a normal number. v = m 2^e (m < 2^53), and its 17
// significant digits are v 10^q = m 5^q 2^(e + q) (q = 16 - the decimal
// exponent, at most 26 here, so m 5^q < 2^117), rounded to the nearest
// integer, ties to even, as printf rounds. Then printf's %g layout: fixed
// for decimal exponents -4 .. 16, else scientific with at least two
// exponent digits, trailing zeros removed. About twice as fast as
// std::to_chars with a precision (a fw CDFX holds ~3000 such values);
// tests/tables/number_format_test.cc compares it with printf. False
// outside that range (the caller formats otherwise).
bool AppendSeventeenDigits(std::string* out, double v) {
  uint64_t bits;
  std::memcpy(&bits, &v, 8);
  const int biased = static_cast<int>((bits >> 52) & 0x7ff);
  const double a = std::abs(v);
  if (biased == 0 || !(a >= 1e-10 && a < 1e16)) return false;
  const uint64_t m = (bits & ((uint64_t{1} << 52) - 1)) | (uint64_t{1} << 52);
  const int e = biased - 1075;
  // v in [2^b, 2^(b + 1)): the decimal exponent x is floor(b log10 2) or
  // one more (78913 / 2^18: log10 2 to 2e-7, exact for the b here).
  const int b = e + 52;
  int x = (b * 78913) >> 18;
  static constexpr uint64_t kPow5[] = {1ull, 5ull, 25ull, 125ull, 625ull, 3125ull, 15625ull, 78125ull, 390625ull,
                                       1953125ull, 9765625ull, 48828125ull, 244140625ull, 1220703125ull,
                                       6103515625ull, 30517578125ull, 152587890625ull, 762939453125ull,
                                       3814697265625ull, 19073486328125ull, 95367431640625ull, 476837158203125ull,
                                       2384185791015625ull, 11920928955078125ull, 59604644775390625ull,
                                       298023223876953125ull, 1490116119384765625ull, 7450580596923828125ull};
  constexpr uint64_t k16 = 10000000000000000ull, k17 = 100000000000000000ull;
  using U128 = unsigned __int128;
  uint64_t n = 0;
  for (int attempt = 0; attempt < 3 && n == 0; ++attempt) {
    const int q = 16 - x;
    if (q < 0 || q > 27) return false;
    const U128 p = static_cast<U128>(m) * kPow5[q];   // v 10^q = p 2^(e + q)
    const int sh = -(e + q);
    U128 whole, rem = 0, half = 0;
    if (sh <= 0) {
      if (-sh > 10) return false;
      whole = p << -sh;
    } else {
      if (sh >= 127) return false;
      whole = p >> sh;
      rem = p & ((static_cast<U128>(1) << sh) - 1);
      half = static_cast<U128>(1) << (sh - 1);
    }
    if (whole >= k17) { ++x; continue; }
    if (whole < k16) { --x; continue; }
    n = static_cast<uint64_t>(whole);
    if (rem > half || (sh > 0 && rem == half && (n & 1))) ++n;
    if (n == k17) { n = k16; ++x; }
  }
  if (n == 0) return false;
  char d[20];
  std::to_chars(d, d + sizeof d, n);   // 17 digits
  int len = 17;
  while (len > 1 && d[len - 1] == '0') --len;
  char buf[32];
  char* o = buf;
  if (v < 0) *o++ = '-';
  if (x < -4 || x >= 17) {
    *o++ = d[0];
    if (len > 1) {
      *o++ = '.';
      std::memcpy(o, d + 1, len - 1);
      o += len - 1;
    }
    *o++ = 'e';
    *o++ = x < 0 ? '-' : '+';
    const int ax = std::abs(x);
    if (ax < 10) *o++ = '0';
    o = std::to_chars(o, buf + sizeof buf, ax).ptr;
  } else if (x >= 0) {
    std::memcpy(o, d, x + 1);
    o += x + 1;
    if (len > x + 1) {
      *o++ = '.';
      std::memcpy(o, d + x + 1, len - x - 1);
      o += len - x - 1;
    }
  } else {
    *o++ = '0';
    *o++ = '.';
    for (int k = 0; k < -x - 1; ++k) *o++ = '0';
    std::memcpy(o, d, len);
    o += len;
  }
  out->append(buf, o);
  return true;
}

}  // namespace

// std::to_chars with a precision formats as printf's "%.17g" does in the C
// locale ([charconv.to.chars]), without printf's parsing of the format per
// value: a 64 x 32 CDFX map writes ~10^4 of them.
std::string Num(double v) {
  std::string s;
  AppendNum(&s, v);
  return s;
}

void AppendNum(std::string* out, double v) {
  if (!std::isfinite(v)) {
    out->append(absl::StrFormat("%.17g", v));
    return;
  }
  char buf[32];
  // Whole numbers (the flags' 0 and 1, round axis breakpoints) as integers:
  // "%.17g" writes an integer below 10^17 in magnitude as its digits, no
  // point or exponent; std::to_chars of the integer is the same bytes and
  // much cheaper than the 17-digit float conversion. (-0 keeps its sign
  // through the float path.)
  if (v == std::trunc(v) && std::abs(v) < 1e15 && !(v == 0 && std::signbit(v))) {
    const auto r = std::to_chars(buf, buf + sizeof buf, static_cast<long long>(v));
    out->append(buf, r.ptr);
    return;
  }
  if (AppendSeventeenDigits(out, v)) return;
  const auto r = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 17);
  out->append(buf, r.ptr);
}

std::string Crc(const Table& t) { return absl::StrFormat("%08x", t.crc32); }

std::vector<double> AsDoubles(const std::vector<uint8_t>& v) { return std::vector<double>(v.begin(), v.end()); }

}  // namespace internal

using internal::Cdfx;
using internal::CHeader;
using internal::Csv;
using internal::Dcm;
using internal::Json;

const char* FluxcalVersion() { return FLUXCAL_VERSION; }

std::string PayloadBytes(const Table& t) {
  std::string out;
  size_t n = 0;
  for (const auto& a : t.axes) n += a.values.size();
  for (const auto& o : t.outputs) n += o.values.size();
  out.reserve(8 * n);
  // Each double's IEEE 754 bits, little-endian: on a little-endian host the
  // bytes in memory, copied whole.
  auto put = [&](const std::vector<double>& v) {
    if constexpr (std::endian::native == std::endian::little) {
      out.append(reinterpret_cast<const char*>(v.data()), 8 * v.size());
    } else {
      for (double x : v) {
        uint64_t bits;
        std::memcpy(&bits, &x, 8);
        for (int b = 0; b < 8; ++b) out.push_back(static_cast<char>((bits >> (8 * b)) & 0xff));
      }
    }
  };
  for (const auto& a : t.axes) put(a.values);
  for (const auto& o : t.outputs) put(o.values);
  return out;
}

void Seal(Table* t) {
  const std::string p = PayloadBytes(*t);
  t->crc32 = static_cast<uint32_t>(::crc32(0L, reinterpret_cast<const Bytef*>(p.data()),
                                           static_cast<uInt>(p.size())));
  t->sha256 = io::Sha256Hex(p);
}

absl::StatusOr<Format> ParseFormat(const std::string& name) {
  if (name == "csv") return Format::kCsv;
  if (name == "json") return Format::kJson;
  if (name == "h") return Format::kCHeader;
  if (name == "cdfx") return Format::kCdfx;
  if (name == "dcm") return Format::kDcm;
  if (name == "a2l") return Format::kA2l;
  return absl::InvalidArgumentError(
      absl::StrCat("flag --format: expected csv, json, h, cdfx, dcm or a2l, got '", name, "'"));
}

std::string UnitOf(const std::string& name) {
  auto ends = [&](const char* suf) {
    const size_t n = std::strlen(suf);
    return name.size() > n && name.compare(name.size() - n, n, suf) == 0;
  };
  if (ends("_nm")) return "Nm";
  if (ends("_rpm")) return "rpm";
  if (ends("_wb")) return "Wb";
  if (ends("_ohm")) return "Ohm";
  if (ends("_v")) return "V";
  if (ends("_c")) return "degC";
  if (ends("_a")) return "A";
  if (ends("_w")) return "W";
  return "-";
}

std::string Label(const Table& t, const std::string& name) {
  return absl::AsciiStrToUpper(
      absl::StrCat("FLUXCAL_", t.kind, t.label_tag.empty() ? "" : "_", t.label_tag, "_", name));
}

std::string CSymbol(const Table& t, const std::string& name) { return absl::AsciiStrToLower(Label(t, name)); }

// One sentence on the axis order, the same in every format (docs/tables.md).
std::string AxisOrder(const Table& t) {
  if (t.axes.size() == 1) return absl::StrCat("X = ", t.axes[0].name, " (one axis)");
  return absl::StrCat("X = ", t.axes[0].name, " (first axis), Y = ", t.axes[1].name,
                      " (second axis); flat arrays index [ix * ", t.axes[1].values.size(), " + iy], X slowest");
}

// Text that goes into a comment: one line, no comment terminators.
std::string OneLine(std::string s) {
  for (auto& c : s) if (c == '\n' || c == '\r') c = ' ';
  return absl::StrReplaceAll(s, {{"*/", "* /"}, {"--", "- -"}});
}

std::vector<Scalar> Scalars(const Table& t) {
  const auto& l = t.limits;
  // Rs, Udc and u_max only when they were given: an MTPA table computed
  // without them does not state a voltage it never used.
  std::vector<Scalar> s = {
      {"pole_pairs", static_cast<double>(l.pole_pairs), "-", "pole pairs p of the calibration", true}};
  if (l.rs_ohm) s.push_back({"rs_ohm", *l.rs_ohm, "Ohm", "phase resistance Rs used for the steady-state voltage", false});
  s.push_back({"psi_pm_wb", t.psi_pm_wb, "Wb", "permanent-magnet flux linkage psi_d(0, 0) of the fitted model", false});
  s.push_back({"i_max_a", l.i_max_a, "A", "current limit the table was computed for (peak, amplitude-invariant)", false});
  if (l.udc_v) {
    s.push_back({"udc_v", *l.udc_v, "V", "DC-link voltage the table was computed for", false});
    s.push_back({"modulation_limit", l.modulation_limit, "-", "fraction of the linear SVPWM range used", false});
    s.push_back({"u_max_v", l.UMaxV(), "V", "voltage limit m Udc / sqrt(3) (peak phase, amplitude-invariant)", false});
  }
  s.push_back({"temperature_c", l.temperature_c, "degC", "temperature the flux model was evaluated at", false});
  if (t.measured_current_limit_a > 0) {
    s.push_back({"measured_current_limit_a", t.measured_current_limit_a, "A",
                 "current limit the identified points cover; beyond it cells are flagged extrapolated", false});
  }
  if (t.magnet_temperature) {
    const MagnetTemperature& mt = *t.magnet_temperature;
    s.push_back({"magnet_temperature_c", mt.at_c, "degC", "magnet temperature the table was computed for", false});
    s.push_back({"magnet_reference_c", mt.reference_c, "degC",
                 "magnet temperature of the calibration's flux map", false});
    if (mt.reference_spread_k) {
      s.push_back({"magnet_reference_spread_k", *mt.reference_spread_k, "K",
                   "spread (max - min) of the temperatures the flux map was recorded at", false});
    }
    s.push_back({"magnet_alpha_per_k", mt.alpha_per_k, "1/K",
                 "the calibration's relative change of psi_pm per kelvin", false});
    s.push_back({"psi_pm_scale", mt.Scale(), "-",
                 "psi_pm at magnet_temperature_c over psi_pm of the flux map: 1 + alpha (T - T_ref)", false});
  }
  if (t.kind == "fw" || t.kind == "envelope") {
    s.push_back({"speed_max_rpm", t.speed_max_rpm, "rpm", "top of the speed axis (axis from 0 rpm)", false});
  }
  if (t.kind == "envelope") {
    s.push_back({"torque_sign", t.envelope_generating ? -1.0 : 1.0, "-",
                 "+1: the motoring limit (torque, power >= 0); -1: the generating limit (torque, power <= 0)", true});
  }
  s.push_back({"allow_extrapolation", t.allow_extrapolation ? 1.0 : 0.0, "-",
               "1: computed beyond the measured region on request (allow-extrapolation flag)", true});
  s.push_back({"calibration_version", static_cast<double>(t.calibration_version), "-",
               "stored version of the calibration", true});
  return s;
}

std::vector<std::pair<std::string, std::string>> TextFields(const Table& t) {
  return {{"serial", t.serial},           {"model", t.model},     {"created_utc", t.created_utc},
          {"fluxcal_version", t.fluxcal_version}, {"verdict", t.verdict}, {"release_state", t.release_state}};
}

std::vector<std::pair<std::string, const std::vector<uint8_t>*>> Flags(const Table& t) {
  return {{"clamped", &t.clamped},
          {"extrapolated", &t.extrapolated},
          {"by_symmetry", &t.by_symmetry},
          {"not_positive_definite", &t.not_positive_definite}};
}

absl::StatusOr<CType> ParseCType(const std::string& name) {
  for (CType ct : {CType::kDouble, CType::kFloat, CType::kInt16, CType::kInt32}) {
    if (name == CTypeName(ct)) return ct;
  }
  return absl::InvalidArgumentError(
      absl::StrCat("flag --ctype: expected double, float, int16 or int32, got '", name, "'"));
}

const char* CTypeName(CType ct) {
  switch (ct) {
    case CType::kFloat: return "float";
    case CType::kInt16: return "int16";
    case CType::kInt32: return "int32";
    case CType::kDouble: break;
  }
  return "double";
}

int FixedPointBits(CType ct) { return ct == CType::kInt16 ? 16 : ct == CType::kInt32 ? 32 : 0; }

absl::StatusOr<Exported> Export(const Table& t, Format f, const ExportOptions& opt) {
  if (t.axes.empty() || t.outputs.empty()) return absl::InvalidArgumentError("table: no axes or no outputs");
  size_t cells = 1;
  for (const auto& a : t.axes) {
    cells *= a.values.size();
    for (double v : a.values) {
      if (!std::isfinite(v)) return absl::InvalidArgumentError(absl::StrCat("table axis '", a.name, "': non-finite value"));
    }
  }
  for (const auto& o : t.outputs) {
    if (o.values.size() != cells) {
      return absl::InvalidArgumentError(absl::StrCat("table output '", o.name, "': ", o.values.size(),
                                                     " values for ", cells, " cells"));
    }
    for (double v : o.values) {
      if (!std::isfinite(v)) return absl::InvalidArgumentError(absl::StrCat("table output '", o.name, "': non-finite value"));
    }
  }
  for (const auto& [name, v] : Flags(t)) {
    if (v->size() != cells) {
      return absl::InvalidArgumentError(absl::StrCat("table flags '", name, "': ", v->size(), " for ", cells, " cells"));
    }
  }
  Exported e;
  const std::vector<QuantityScale> scales = QuantityScales(t, opt.ctype);
  if ((f == Format::kCHeader || f == Format::kA2l) && FixedPointBits(opt.ctype) > 0) e.fixed_point = scales;
  switch (f) {
    case Format::kCsv: e.bytes = Csv(t); break;
    case Format::kJson: e.bytes = Json(t); break;
    case Format::kCHeader: {
      auto h = CHeader(t, opt.ctype, scales);
      if (!h.ok()) return h.status();
      e.bytes = *std::move(h);
      break;
    }
    case Format::kCdfx: e.bytes = Cdfx(t); break;
    case Format::kDcm: e.bytes = Dcm(t); break;
    case Format::kA2l: {
      e.bytes = A2lDescription(t, opt.ctype, scales);
      break;
    }
  }
  e.payload_crc32 = t.crc32;
  e.payload_sha256 = t.sha256;
  e.file_sha256 = io::Sha256Hex(e.bytes);
  return e;
}

}  // namespace fluxcal::tables
