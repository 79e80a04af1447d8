// The A2L writer (tables/a2l.h). Keyword structure and positional fields
// after ASAM MCD-2 MC 1.71; what is emitted and why: docs/tables.md, "A2L".
#include "tables/a2l.h"

#include <algorithm>
#include <cmath>

#include "absl/strings/ascii.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_replace.h"
#include "tables/internal_formats.h"

namespace fluxcal::tables {
namespace {

std::string Num(double v) { return absl::StrFormat("%.17g", v == 0 ? 0.0 : v); }

// An ASAP2 string: one line in double quotes. A quote or backslash inside,
// which ASAP2 versions escape differently (\" since 1.6, "" before), is
// written as ' or /, so that every reader takes the same text.
std::string Str(const std::string& s) {
  return absl::StrCat("\"", absl::StrReplaceAll(OneLine(s), {{"\"", "'"}, {"\\", "/"}}), "\"");
}

// The ASAP2 data type of a C element type (C99 7.18.1.1: int16_t and
// int32_t are two's complement, as SWORD and SLONG).
const char* Datatype(CType ct) {
  switch (ct) {
    case CType::kFloat: return "FLOAT32_IEEE";
    case CType::kInt16: return "SWORD";
    case CType::kInt32: return "SLONG";
    case CType::kDouble: break;
  }
  return "FLOAT64_IEEE";
}

// The quantity a unit measures, for the COMPU_METHOD names.
std::string Quantity(const std::string& unit) {
  if (unit == "A") return "current_a";
  if (unit == "Nm") return "torque_nm";
  if (unit == "rpm") return "speed_rpm";
  if (unit == "Wb") return "flux_wb";
  if (unit == "V") return "voltage_v";
  if (unit == "W") return "power_w";
  if (unit == "Ohm") return "resistance_ohm";
  if (unit == "degC") return "temperature_c";
  if (unit == "-") return "dimensionless";
  std::string s = "unit_";
  for (char c : unit) s += absl::ascii_isalnum(static_cast<unsigned char>(c)) ? absl::ascii_tolower(c) : '_';
  return s;
}

// ASAP2 display format "%Length.Layout": enough decimals to tell LSB steps
// apart (fixed point) or nine significant digits (floating).
std::string DisplayFormat(double full_scale, double lsb) {
  const int int_digits = std::max(1, static_cast<int>(std::floor(std::log10(full_scale))) + 1);
  const int decimals = lsb > 0 ? std::max(0, static_cast<int>(std::ceil(-std::log10(lsb) - 1e-9)) + 1)
                               : std::max(1, 9 - int_digits);
  return absl::StrFormat("%%%d.%d", int_digits + decimals + 2, decimals);
}

struct Conversion {
  std::string name, unit;
  double full_scale = 1;
  const QuantityScale* fixed = nullptr;   // RAT_FUNC of this scale; IDENTICAL when null
};

class A2lWriter {
 public:
  A2lWriter(const Table& t, CType ct, const std::vector<QuantityScale>& scales)
      : t_(t), ct_(ct), scales_(scales), fixed_(FixedPointBits(ct) > 0) {}

  std::string Write();

 private:
  // The COMPU_METHOD of an axis or output; of a scalar (always IDENTICAL:
  // scalars are constants written as decimals); of the 0/1 flags.
  // Each returns the COMPU_METHOD's name (the list grows as they are asked for).
  std::string ArrayConversion(const std::string& name);
  std::string IdenticalConversion(const std::string& unit, double full_scale);
  std::string Layout(const char* kind, const char* datatype);
  double Lower(const std::string& name) const;
  double Upper(const std::string& name) const;

  void Line(int indent, const std::string& text) { body_ += std::string(2 * indent, ' ') + text + "\n"; }
  // A positional field, one a line, with the standard's name for it.
  void Field(int indent, const std::string& value, const char* what) {
    Line(indent, absl::StrFormat("%-44s /* %s */", value, what));
  }
  void Annotation(int indent, const std::string& label, const std::vector<std::string>& text);
  void AxisDescrs(int indent);
  void TableCharacteristic(const std::string& name, const std::string& long_id, const std::string& cm,
                           const char* datatype, double lower, double upper, bool read_only,
                           const std::vector<std::string>& notes);

  const Table& t_;
  const CType ct_;
  const std::vector<QuantityScale>& scales_;
  const bool fixed_;
  std::vector<Conversion> conversions_;
  std::vector<std::pair<std::string, std::string>> layouts_;   // name, its one line
  std::string body_;
};

std::string A2lWriter::ArrayConversion(const std::string& name) {
  const QuantityScale* q = ScaleOf(scales_, name);
  if (q == nullptr || !fixed_) return IdenticalConversion(UnitOf(name), q != nullptr ? q->full_scale : 1.0);
  const std::string cm = Label(t_, absl::StrCat("cm_", Quantity(q->unit), "_", CTypeName(ct_)));
  for (const auto& c : conversions_) {
    if (c.name == cm) return cm;
  }
  conversions_.push_back({cm, q->unit, q->full_scale, q});
  return cm;
}

std::string A2lWriter::IdenticalConversion(const std::string& unit, double full_scale) {
  const std::string cm = Label(t_, absl::StrCat("cm_", Quantity(unit)));
  for (auto& c : conversions_) {
    if (c.name == cm) {
      c.full_scale = std::max(c.full_scale, full_scale);
      return cm;
    }
  }
  conversions_.push_back({cm, unit, full_scale, nullptr});
  return cm;
}

std::string A2lWriter::Layout(const char* kind, const char* datatype) {
  const bool axis = std::string(kind) == "axis";
  const std::string name = Label(t_, absl::StrCat("rl_", kind, "_", datatype));
  for (const auto& [n, line] : layouts_) {
    if (n == name) return name;
  }
  // FNC_VALUES Position Datatype IndexMode AddressType: the values from
  // byte 0 of the C object; COLUMN_DIR stores a map column by column (all
  // Y of the first X, then the next X), i.e. X slowest as the C arrays
  // (docs/tables.md, axis order). AXIS_PTS_X Position Datatype IndexIncr
  // Addressing: the breakpoints, ascending with the address.
  layouts_.push_back({name, axis ? absl::StrCat("AXIS_PTS_X 1 ", datatype, " INDEX_INCR DIRECT")
                                 : absl::StrCat("FNC_VALUES 1 ", datatype, " COLUMN_DIR DIRECT")});
  return name;
}

// Limits of an axis or output: the range its representation holds
// (fixed point) or its full scale (floating).
double A2lWriter::Lower(const std::string& name) const {
  const QuantityScale* q = ScaleOf(scales_, name);
  return q != nullptr ? q->min_value : 0.0;
}
double A2lWriter::Upper(const std::string& name) const {
  const QuantityScale* q = ScaleOf(scales_, name);
  return q != nullptr ? q->max_value : 1.0;
}

void A2lWriter::Annotation(int indent, const std::string& label, const std::vector<std::string>& text) {
  Line(indent, "/begin ANNOTATION");
  Line(indent + 1, absl::StrCat("ANNOTATION_LABEL ", Str(label)));
  Line(indent + 1, absl::StrCat("ANNOTATION_ORIGIN ", Str(absl::StrCat("fluxcal ", t_.fluxcal_version))));
  Line(indent + 1, "/begin ANNOTATION_TEXT");
  for (const auto& s : text) Line(indent + 2, Str(s));
  Line(indent + 1, "/end ANNOTATION_TEXT");
  Line(indent, "/end ANNOTATION");
}

// One AXIS_DESCR per axis, X (first axis) then Y: COM_AXIS, the breakpoints
// in the AXIS_PTS of that name.
void A2lWriter::AxisDescrs(int indent) {
  for (const auto& a : t_.axes) {
    const std::string cm = ArrayConversion(a.name);
    Line(indent, "/begin AXIS_DESCR");
    Field(indent + 1, "COM_AXIS", "Attribute");
    Field(indent + 1, "NO_INPUT_QUANTITY", "InputQuantity");
    Field(indent + 1, cm, "Conversion");
    Field(indent + 1, absl::StrCat(a.values.size()), "MaxAxisPoints");
    Field(indent + 1, Num(Lower(a.name)), "LowerLimit");
    Field(indent + 1, Num(Upper(a.name)), "UpperLimit");
    Line(indent + 1, absl::StrCat("AXIS_PTS_REF ", Label(t_, a.name)));
    Line(indent, "/end AXIS_DESCR");
  }
}

void A2lWriter::TableCharacteristic(const std::string& name, const std::string& long_id, const std::string& cm,
                                    const char* datatype, double lower, double upper, bool read_only,
                                    const std::vector<std::string>& notes) {
  Line(2, absl::StrCat("/begin CHARACTERISTIC ", Label(t_, name)));
  Field(3, Str(long_id), "LongIdentifier");
  Field(3, t_.axes.size() > 1 ? "MAP" : "CURVE", "Type");
  Field(3, "0x0", "Address (symbolic: SYMBOL_LINK)");
  Field(3, Layout("values", datatype), "Deposit");
  Field(3, "0", "MaxDiff");
  Field(3, cm, "Conversion");
  Field(3, Num(lower), "LowerLimit");
  Field(3, Num(upper), "UpperLimit");
  AxisDescrs(3);
  if (read_only) Line(3, "READ_ONLY");
  Line(3, absl::StrCat("SYMBOL_LINK ", Str(CSymbol(t_, name)), " 0"));
  Annotation(3, "fluxcal provenance", notes);
  Line(2, absl::StrCat("/end CHARACTERISTIC"));
}

std::string A2lWriter::Write() {
  const char* dt = Datatype(ct_);
  const std::string crc = absl::StrFormat("%08x", t_.crc32);
  const std::string checksums = absl::StrCat("payload_crc32 ", crc, ", payload_sha256 ", t_.sha256,
                                             ": over the values (fluxcal docs/tables.md), not over a file");
  std::vector<std::string> provenance;
  for (const auto& [k, v] : TextFields(t_)) provenance.push_back(absl::StrCat(k, ": ", v));
  provenance.push_back(absl::StrCat("calibration_version: ", t_.calibration_version));
  provenance.push_back(absl::StrCat("axis order: ", AxisOrder(t_)));
  provenance.push_back(checksums);
  std::vector<std::string> axis_names;
  for (const auto& a : t_.axes) axis_names.push_back(a.name);
  const std::string over = absl::StrJoin(axis_names, " x ");

  // Axes: one AXIS_PTS each, shared by every output and flag.
  for (size_t i = 0; i < t_.axes.size(); ++i) {
    const Axis& a = t_.axes[i];
    const std::string cm = ArrayConversion(a.name);
    Line(2, absl::StrCat("/begin AXIS_PTS ", Label(t_, a.name)));
    Field(3, Str(absl::StrFormat("%s: %s axis (%s) of the %s table, shared by its outputs and flags", a.name,
                                 i == 0 ? "first" : "second", i == 0 ? "X" : "Y", t_.kind)),
          "LongIdentifier");
    Field(3, "0x0", "Address (symbolic: SYMBOL_LINK)");
    Field(3, "NO_INPUT_QUANTITY", "InputQuantity");
    Field(3, Layout("axis", dt), "Deposit");
    Field(3, "0", "MaxDiff");
    Field(3, cm, "Conversion");
    Field(3, absl::StrCat(a.values.size()), "MaxAxisPoints");
    Field(3, Num(Lower(a.name)), "LowerLimit");
    Field(3, Num(Upper(a.name)), "UpperLimit");
    Line(3, "MONOTONY STRICT_INCREASE");
    Line(3, absl::StrCat("SYMBOL_LINK ", Str(CSymbol(t_, a.name)), " 0"));
    Line(2, "/end AXIS_PTS");
  }
  // Outputs and flags: CURVE or MAP over the axes.
  for (const auto& o : t_.outputs) {
    std::vector<std::string> notes = provenance;
    const QuantityScale* q = ScaleOf(scales_, o.name);
    if (fixed_ && q != nullptr) {
      notes.push_back(absl::StrFormat(
          "%s fixed point: physical = raw * %s %s + %s %s, raw rounded to the nearest integer (error at most LSB/2)",
          CTypeName(ct_), Num(q->lsb), q->unit, Num(q->offset), q->unit));
    }
    TableCharacteristic(o.name, absl::StrCat(o.name, " over ", over), ArrayConversion(o.name), dt, Lower(o.name),
                        Upper(o.name), false, notes);
  }
  for (const auto& [name, v] : Flags(t_)) {
    TableCharacteristic(name, absl::StrCat(name, " (0/1 per cell) over ", over), IdenticalConversion("-", 1.0),
                        "UBYTE", 0.0, 1.0, true, provenance);
  }
  // Scalars: #define constants of the C header, no object in memory.
  for (const auto& sc : Scalars(t_)) {
    const QuantityScale* q = nullptr;
    for (const auto& s : scales_) {
      if (s.unit == sc.unit) q = &s;
    }
    const double fs = q != nullptr ? q->full_scale : FullScale(std::abs(sc.value));
    const std::string cm = IdenticalConversion(sc.unit, fs);
    Line(2, absl::StrCat("/begin CHARACTERISTIC ", Label(t_, sc.name)));
    Field(3, Str(sc.description), "LongIdentifier");
    Field(3, "VALUE", "Type");
    Field(3, "0x0", "Address (no object: a C #define)");
    Field(3, Layout("values", sc.integer ? "SLONG" : ct_ == CType::kFloat ? "FLOAT32_IEEE" : "FLOAT64_IEEE"),
          "Deposit");
    Field(3, "0", "MaxDiff");
    Field(3, cm, "Conversion");
    Field(3, Num(-fs), "LowerLimit");
    Field(3, Num(fs), "UpperLimit");
    Line(3, "READ_ONLY");
    Annotation(3, "C header", {absl::StrCat("#define ", Label(t_, sc.name), " (", Num(sc.value), " ", sc.unit,
                                            "): a compile-time constant with no object in ECU memory (no "
                                            "SYMBOL_LINK); the value the table was computed for, as in the CDFX and "
                                            "DCM")});
    Line(2, "/end CHARACTERISTIC");
  }
  // Text fields: the C header's char arrays (NUMBER counts the NUL).
  for (const auto& [k, v] : TextFields(t_)) {
    Line(2, absl::StrCat("/begin CHARACTERISTIC ", Label(t_, k)));
    Field(3, Str(k), "LongIdentifier");
    Field(3, "ASCII", "Type");
    Field(3, "0x0", "Address (symbolic: SYMBOL_LINK)");
    Field(3, Layout("values", "UBYTE"), "Deposit");
    Field(3, "0", "MaxDiff");
    Field(3, "NO_COMPU_METHOD", "Conversion");
    Field(3, "0", "LowerLimit");
    Field(3, "255", "UpperLimit");
    Line(3, absl::StrCat("NUMBER ", OneLine(v).size() + 1));
    Line(3, "READ_ONLY");
    Line(3, absl::StrCat("SYMBOL_LINK ", Str(CSymbol(t_, k)), " 0"));
    Line(2, "/end CHARACTERISTIC");
  }

  // Assembled: comment, PROJECT > HEADER, MODULE > MOD_PAR, MOD_COMMON,
  // COMPU_METHOD, RECORD_LAYOUT, then the objects above.
  const std::string kind =
      absl::AsciiStrToUpper(absl::StrCat(t_.kind, t_.label_tag.empty() ? "" : "_", t_.label_tag));
  std::string s = absl::StrFormat(
      "/* fluxcal %s table: ASAM MCD-2 MC (ASAP2) 1.71 description of the C header that\n"
      " * `fluxcal export --format h --ctype %s` writes for the same table.\n",
      t_.kind, CTypeName(ct_));
  for (const auto& p : provenance) s += absl::StrCat(" * ", OneLine(p), "\n");
  s += absl::StrCat(
      " * Names: the labels of the CDFX and DCM files; the C header's variables are their lower-case\n"
      " * form (SYMBOL_LINK), its macros the labels themselves.\n"
      " * Addresses: every object is at 0x0 with SYMBOL_LINK \"<C variable>\" 0, to be resolved from the\n"
      " * ECU build's linker map by the A2L address update of its tool chain. The scalars are #define\n"
      " * constants of the C header, no object in memory: VALUE, READ_ONLY, without SYMBOL_LINK.\n"
      " * Byte order: MSB_LAST (little endian) as the Arm Cortex-M/R, TriCore and RH850 targets; change\n"
      " * MOD_COMMON BYTE_ORDER for a big-endian ECU.\n");
  if (fixed_) {
    s += absl::StrFormat(" * Fixed point (%s): physical = raw * LSB + offset, per quantity:\n", CTypeName(ct_));
    for (const auto& q : scales_) {
      s += absl::StrFormat(" *   %s: LSB %s %s, offset %s %s, range %s .. %s %s: %s\n", q.unit, Num(q.lsb), q.unit,
                           Num(q.offset), q.unit, Num(q.min_value), Num(q.max_value), q.unit,
                           absl::StrJoin(q.arrays, ", "));
    }
  }
  s += " */\n";
  s += "ASAP2_VERSION 1 71\n";
  s += absl::StrFormat("/begin PROJECT FLUXCAL_%s %s\n", kind,
                       Str(absl::StrFormat("fluxcal %s table of %s, calibration version %d", internal::TableTitle(t_), t_.serial,
                                           t_.calibration_version)));
  s += absl::StrFormat("  /begin HEADER %s\n    VERSION %s\n  /end HEADER\n",
                       Str(absl::StrFormat("fluxcal %s table", internal::TableTitle(t_))),
                       Str(absl::StrCat("calibration version ", t_.calibration_version)));
  s += absl::StrFormat("  /begin MODULE FLUXCAL_%s %s\n", kind,
                       Str(absl::StrFormat("%s table, %s", internal::TableTitle(t_), AxisOrder(t_))));
  s += absl::StrFormat("    /begin MOD_PAR %s\n", Str(absl::StrCat("fluxcal ", internal::TableTitle(t_), " table of ", t_.serial)));
  s += absl::StrFormat("      VERSION %s\n", Str(absl::StrCat("fluxcal ", t_.fluxcal_version)));
  for (const auto& [k, v] : TextFields(t_)) {
    s += absl::StrFormat("      SYSTEM_CONSTANT %s %s\n", Str(Label(t_, k)), Str(v));
  }
  s += absl::StrFormat("      SYSTEM_CONSTANT %s %s\n", Str(Label(t_, "calibration_version")),
                       Str(absl::StrCat(t_.calibration_version)));
  s += absl::StrFormat("      SYSTEM_CONSTANT %s %s\n", Str(Label(t_, "payload_crc32")), Str(crc));
  s += absl::StrFormat("      SYSTEM_CONSTANT %s %s\n", Str(Label(t_, "payload_sha256")), Str(t_.sha256));
  s += "    /end MOD_PAR\n";
  // Natural alignment: each C object starts at a multiple of its element
  // size, as a C compiler places it.
  s += "    /begin MOD_COMMON \"little endian, natural alignment\"\n"
       "      BYTE_ORDER MSB_LAST\n      DEPOSIT ABSOLUTE\n      ALIGNMENT_BYTE 1\n      ALIGNMENT_WORD 2\n"
       "      ALIGNMENT_LONG 4\n      ALIGNMENT_FLOAT32_IEEE 4\n      ALIGNMENT_FLOAT64_IEEE 8\n"
       "    /end MOD_COMMON\n";
  for (const auto& c : conversions_) {
    s += absl::StrCat("    /begin COMPU_METHOD ", c.name, "\n");
    if (c.fixed != nullptr) {
      const QuantityScale& q = *c.fixed;
      s += absl::StrFormat("      %s\n      RAT_FUNC %s %s\n",
                           Str(absl::StrFormat("%s [%s], %s fixed point: physical = %s * raw + %s", Quantity(q.unit),
                                               q.unit, CTypeName(ct_), Num(q.lsb), Num(q.offset))),
                           Str(DisplayFormat(q.full_scale, q.lsb)), Str(q.unit));
      // RAT_FUNC: raw = (a p^2 + b p + c) / (d p^2 + e p + f), p physical
      // (ASAP2 COEFFS); raw = (p - offset) / LSB gives a = 0, b = 1,
      // c = -offset, d = 0, e = 0, f = LSB.
      s += absl::StrFormat("      COEFFS 0 1 %s 0 0 %s\n", Num(0.0 - q.offset), Num(q.lsb));
    } else {
      s += absl::StrFormat("      %s\n      IDENTICAL %s %s\n",
                           Str(absl::StrFormat("%s [%s], physical value as stored", Quantity(c.unit), c.unit)),
                           Str(DisplayFormat(c.full_scale, 0.0)), Str(c.unit));
    }
    s += "    /end COMPU_METHOD\n";
  }
  for (const auto& [name, line] : layouts_) {
    s += absl::StrCat("    /begin RECORD_LAYOUT ", name, "\n      ", line, "\n    /end RECORD_LAYOUT\n");
  }
  s += body_;
  s += "  /end MODULE\n/end PROJECT\n";
  return s;
}

}  // namespace

std::string A2lDescription(const Table& t, CType ct, const std::vector<QuantityScale>& scales) {
  return A2lWriter(t, ct, scales).Write();
}

}  // namespace fluxcal::tables
