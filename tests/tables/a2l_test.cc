// The A2L export checked by a separate reader (a2l_reader.h, written from
// the ASAP2 keyword structure, sharing no code with tables/a2l.cc) against
// the C header, CDFX and DCM of the same table: names, axes, point counts,
// values through the A2L's COMPU_METHODs from the header's numbers, units,
// record layouts and provenance. And the fixed-point representation
// (--ctype int16 / int32): power-of-two LSB with headroom, round-trip error
// at most LSB/2, saturation refused, a header that compiles.
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <random>
#include <sstream>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_join.h"
#include "absl/strings/str_split.h"
#include "gtest/gtest.h"
#include "tables/export_rule.h"
#include "tables/tables.h"
#include "tests/tables/a2l_reader.h"
#include "tests/tables/c_unit.h"
#include "tests/tables/export_readers.h"
#include "tests/tables/twin_limits.h"

namespace fluxcal::tables {
namespace {

namespace ar = ::fluxcal::a2l_reader;
using readers::Parsed;

// The twin's calibration (with Udc and Rs) and tables of it as the export
// rule builds them: an MTPA curve, an MTPV curve and a field-weakening map.
const fit::Calibration& Twin() {
  static const auto* c = new fit::Calibration(TwinCalibration(sim::DriveParams().udc_v, sim::MotorParams().rs_ohm));
  return *c;
}

Table TwinTable(const std::string& kind) {
  TableSpec spec;
  spec.kind = kind;
  spec.points = kind == "fw" ? 9 : 17;
  spec.speed_points = 7;
  spec.speed_max_rpm = 6000;
  spec.verdict = "pass";
  spec.release_state = kNotReleased;
  auto b = BuildExportTable(Twin(), spec, {});
  EXPECT_TRUE(b.ok()) << kind << ": " << b.status();
  return b->table;
}

const char* A2lDatatypeOf(const std::string& c_type) {
  if (c_type == "double") return "FLOAT64_IEEE";
  if (c_type == "float") return "FLOAT32_IEEE";
  if (c_type == "int16_t") return "SWORD";
  if (c_type == "int32_t") return "SLONG";
  if (c_type == "uint8_t") return "UBYTE";
  return "?";
}

// Whether a value read back from the header (`got`, through the A2L's
// conversion) is the table's `want` in the representation: equal for
// double, the same binary32 for float, within half an LSB in fixed point.
::testing::AssertionResult Carries(CType ct, double got, double want, double lsb) {
  const bool ok = ct == CType::kFloat ? static_cast<float>(got) == static_cast<float>(want)
                  : FixedPointBits(ct) > 0 ? std::abs(got - want) <= 0.5 * lsb
                                          : got == want;
  if (ok) return ::testing::AssertionSuccess();
  return ::testing::AssertionFailure() << "expected " << want << ", got " << got << " (" << CTypeName(ct)
                                       << (lsb > 0 ? absl::StrCat(", LSB ", lsb) : std::string()) << ")";
}

struct Exports {
  std::string h, cdfx, dcm, a2l;
};
Exports ExportAll(const Table& t, CType ct) {
  Exports e;
  ExportOptions o;
  o.ctype = ct;
  for (auto [f, out] : {std::pair<Format, std::string*>{Format::kCHeader, &e.h}, {Format::kCdfx, &e.cdfx},
                        {Format::kDcm, &e.dcm}, {Format::kA2l, &e.a2l}}) {
    auto x = Export(t, f, o);
    EXPECT_TRUE(x.ok()) << x.status();
    if (x.ok()) *out = x->bytes;
  }
  return e;
}

// The A2L against the C header, CDFX and DCM of the same table and ctype.
void CrossCheck(const Table& t, CType ct) {
  const std::string what = absl::StrCat(t.kind, " ", CTypeName(ct));
  SCOPED_TRACE(what);
  const Exports e = ExportAll(t, ct);
  auto file = ar::ReadA2l(e.a2l, what + ".a2l");
  ASSERT_TRUE(file.ok()) << file.status();
  EXPECT_EQ(file->version_no, 1);
  EXPECT_EQ(file->upgrade_no, 71);
  ASSERT_EQ(file->modules.size(), 1u);
  const ar::Module& m = file->modules[0];
  EXPECT_EQ(m.byte_order, "MSB_LAST");
  EXPECT_EQ(m.alignments.at("ALIGNMENT_WORD"), 2);
  EXPECT_EQ(m.alignments.at("ALIGNMENT_FLOAT64_IEEE"), 8);
  const Parsed ch = readers::ParseCHeader(t, e.h);
  const Parsed cd = readers::ParseCdfx(t, e.cdfx);
  const Parsed dc = readers::ParseDcm(t, e.dcm);
  auto cm_of = [&](const std::string& name) -> const ar::CompuMethod& { return m.compu_methods.at(name); };
  auto phys = [&](const ar::CompuMethod& cm, double raw) {
    auto p = cm.ToPhysical(raw);
    EXPECT_TRUE(p.ok()) << p.status();
    return p.value_or(NAN);
  };
  // The LSB a COMPU_METHOD gives (physical step of one raw count).
  auto lsb_of = [&](const ar::CompuMethod& cm) { return phys(cm, 1.0) - phys(cm, 0.0); };
  const bool fixed = FixedPointBits(ct) > 0;

  // Names: every CHARACTERISTIC is a CDFX label and (text aside, which DCM
  // carries as comments) a DCM label; its C object is the lower-case name
  // (SYMBOL_LINK), a scalar's the #define of the name itself.
  for (const ar::Characteristic& c : m.characteristics) {
    EXPECT_TRUE(cd.labels.count(c.name)) << c.name << " is no CDFX instance";
    if (c.type != "ASCII") {
      EXPECT_TRUE(dc.labels.count(c.name)) << c.name << " is no DCM block";
    }
    if (c.type == "VALUE") {
      EXPECT_TRUE(ch.labels.count(c.name)) << c.name << ": no #define in the C header";
      EXPECT_TRUE(c.symbol_link.empty()) << c.name << ": a #define has no address";
      EXPECT_TRUE(c.read_only) << c.name;
    } else {
      EXPECT_EQ(c.symbol_link, absl::AsciiStrToLower(c.name)) << c.name;
      EXPECT_TRUE(ch.labels.count(c.symbol_link)) << c.symbol_link << ": not a C header variable";
    }
    EXPECT_EQ(c.address, 0u) << c.name;
  }
  // Conversely: every label a calibration tool imports from the CDFX or
  // DCM has its characteristic.
  for (const auto& l : cd.labels) EXPECT_NE(m.FindCharacteristic(l), nullptr) << "CDFX " << l;
  for (const auto& l : dc.labels) EXPECT_NE(m.FindCharacteristic(l), nullptr) << "DCM " << l;

  // Axes: one AXIS_PTS per axis, in the C header as <NAME>_LEN and its
  // array, with the CDFX / DCM breakpoints through its COMPU_METHOD.
  ASSERT_EQ(m.axis_pts.size(), t.axes.size());
  ASSERT_EQ(ch.axes.size(), t.axes.size());
  ASSERT_EQ(cd.axes.size(), t.axes.size());
  ASSERT_EQ(dc.axes.size(), t.axes.size());
  for (size_t k = 0; k < t.axes.size(); ++k) {
    const std::string& axis = t.axes[k].name;
    const ar::AxisPts* p = m.FindAxisPts(Label(t, axis));
    ASSERT_NE(p, nullptr) << axis;
    EXPECT_TRUE(ch.labels.count(p->name + "_LEN")) << p->name;
    EXPECT_EQ(p->symbol_link, CSymbol(t, axis));
    EXPECT_TRUE(ch.labels.count(p->symbol_link)) << p->symbol_link;
    const size_t n = cd.axes[k].size();
    EXPECT_EQ(static_cast<size_t>(p->max_axis_points), n) << axis;
    EXPECT_EQ(ch.axes[k].size(), n) << axis;
    EXPECT_EQ(dc.axes[k].size(), n) << axis;
    EXPECT_EQ(p->monotony, "STRICT_INCREASE");
    const ar::RecordLayout& rl = m.record_layouts.at(p->deposit);
    EXPECT_EQ(rl.axis_datatype, A2lDatatypeOf(ch.element_types.at(axis))) << axis;
    EXPECT_EQ(rl.axis_index_incr, "INDEX_INCR");
    const ar::CompuMethod& cm = cm_of(p->conversion);
    EXPECT_EQ(cm.unit, cd.axis_units[k]) << axis;
    EXPECT_EQ(cm.unit, dc.axis_units[k]) << axis;
    const double lsb = fixed ? lsb_of(cm) : 0.0;
    if (fixed) {
      EXPECT_EQ(ch.lsb.at(axis), lsb) << axis << ": header LSB against COMPU_METHOD";
    }
    for (size_t i = 0; i < n; ++i) {
      const double x = phys(cm, ch.axes[k][i]);
      EXPECT_TRUE(Carries(ct, x, cd.axes[k][i], lsb)) << axis << "[" << i << "] " << cm.unit << ": header via A2L, CDFX";
      EXPECT_TRUE(Carries(ct, x, dc.axes[k][i], lsb)) << axis << "[" << i << "] " << cm.unit << ": header via A2L, DCM";
      EXPECT_GE(x, p->lower_limit) << axis;
      EXPECT_LE(x, p->upper_limit) << axis;
    }
  }

  // Outputs and flags: CURVE / MAP with a COM_AXIS per axis (X then Y),
  // values column by column (X slowest, as the C arrays).
  size_t tables = 0;
  for (const auto& [name, cdfx_values] : cd.arrays) {
    const ar::Characteristic* c = m.FindCharacteristic(Label(t, name));
    ASSERT_NE(c, nullptr) << name;
    ++tables;
    EXPECT_EQ(c->type, t.axes.size() > 1 ? "MAP" : "CURVE") << name;
    ASSERT_EQ(c->axes.size(), t.axes.size()) << name;
    size_t cells = 1;
    for (size_t k = 0; k < t.axes.size(); ++k) {
      EXPECT_EQ(c->axes[k].attribute, "COM_AXIS") << name;
      EXPECT_EQ(c->axes[k].axis_pts_ref, Label(t, t.axes[k].name)) << name << " axis " << k;
      EXPECT_EQ(static_cast<size_t>(c->axes[k].max_axis_points), cd.axes[k].size()) << name;
      cells *= cd.axes[k].size();
    }
    const ar::RecordLayout& rl = m.record_layouts.at(c->deposit);
    EXPECT_EQ(rl.fnc_datatype, A2lDatatypeOf(ch.element_types.at(name))) << name;
    EXPECT_EQ(rl.fnc_index_mode, "COLUMN_DIR") << name;
    const ar::CompuMethod& cm = cm_of(c->conversion);
    EXPECT_EQ(cm.unit, cd.units.at(name)) << name;
    EXPECT_EQ(cm.unit, dc.units.at(name)) << name;
    const std::vector<double>& raw = ch.arrays.at(name);
    ASSERT_EQ(raw.size(), cells) << name;
    ASSERT_EQ(cdfx_values.size(), cells) << name;
    bool flag = false;
    for (const auto& [f, v] : Flags(t)) flag = flag || name == f;
    const double lsb = fixed && !flag ? lsb_of(cm) : 0.0;
    if (fixed && !flag) {
      EXPECT_EQ(ch.lsb.at(name), lsb) << name << ": header LSB against COMPU_METHOD";
    }
    for (size_t i = 0; i < cells; ++i) {
      const double x = phys(cm, raw[i]);
      const CType rep = flag ? CType::kDouble : ct;   // flags are 0/1 integers in every header
      EXPECT_TRUE(Carries(rep, x, cdfx_values[i], lsb)) << name << "[" << i << "] " << cm.unit << ": header via A2L, CDFX";
      EXPECT_TRUE(Carries(rep, x, dc.arrays.at(name)[i], lsb)) << name << "[" << i << "] " << cm.unit
                                                               << ": header via A2L, DCM";
      EXPECT_GE(x, c->lower_limit) << name;
      EXPECT_LE(x, c->upper_limit) << name;
    }
    // Provenance travels with each table: the payload checksums.
    ASSERT_FALSE(c->annotations.empty()) << name;
    const std::string text = absl::StrJoin(c->annotations[0].text, "\n");
    EXPECT_TRUE(absl::StrContains(text, cd.payload_crc32)) << name;
    EXPECT_TRUE(absl::StrContains(text, cd.payload_sha256)) << name;
  }
  EXPECT_EQ(tables, t.outputs.size() + Flags(t).size()) << "outputs and the flags";

  // Scalars: VALUE of the CDFX / DCM unit, within its limits.
  for (const auto& [name, v] : cd.scalars) {
    const ar::Characteristic* c = m.FindCharacteristic(Label(t, name));
    ASSERT_NE(c, nullptr) << name;
    EXPECT_EQ(c->type, "VALUE") << name;
    EXPECT_EQ(cm_of(c->conversion).unit, cd.units.at(name)) << name;
    EXPECT_EQ(cm_of(c->conversion).unit, dc.units.at(name)) << name;
    EXPECT_EQ(cm_of(c->conversion).conversion_type, "IDENTICAL") << name;
    // The header's #define: the value, in float as a binary32 literal.
    EXPECT_TRUE(Carries(ct == CType::kFloat ? ct : CType::kDouble, ch.scalars.at(name), v, 0)) << name;
    EXPECT_GE(v, c->lower_limit) << name;
    EXPECT_LE(v, c->upper_limit) << name;
  }
  // Text: ASCII over the C char arrays, NUMBER = length with the NUL.
  for (const auto& [name, v] : cd.text) {
    const ar::Characteristic* c = m.FindCharacteristic(Label(t, name));
    ASSERT_NE(c, nullptr) << name;
    EXPECT_EQ(c->type, "ASCII") << name;
    EXPECT_EQ(static_cast<size_t>(c->number), ch.text.at(name).size() + 1) << name;
  }
  // The module's constants: provenance and the payload checksums.
  std::map<std::string, std::string> constants(m.system_constants.begin(), m.system_constants.end());
  EXPECT_EQ(constants.at(Label(t, "payload_crc32")), ch.payload_crc32);
  EXPECT_EQ(constants.at(Label(t, "payload_sha256")), ch.payload_sha256);
  EXPECT_EQ(constants.at(Label(t, "serial")), cd.text.at("serial"));
  EXPECT_EQ(constants.at(Label(t, "release_state")), cd.text.at("release_state"));
}

TEST(A2lExport, CrossChecksWithCHeaderCdfxAndDcm) {
  for (const char* kind : {"mtpa", "fw", "mtpv", "envelope"}) {
    const Table t = TwinTable(kind);
    if (t.axes.empty()) continue;
    for (CType ct : {CType::kDouble, CType::kInt16, CType::kInt32, CType::kFloat}) CrossCheck(t, ct);
  }
}

// The tables of a Udc axis carry the voltage in every label; the A2L of
// each still matches its C header, CDFX and DCM (docs/tables.md, "Tables
// over Udc").
TEST(A2lExport, UdcAxisTablesCrossCheckUnderTheirTaggedLabels) {
  for (const char* kind : {"fw", "envelope"}) {
    auto axis = BuildExportTablesOverUdc(Twin(), GridSpec(kind, 9, 7), ClampedAllowed(), {40, 62.5});
    ASSERT_TRUE(axis.ok()) << axis.status();
    for (const auto& b : *axis) {
      EXPECT_FALSE(b.table.label_tag.empty());
      for (CType ct : {CType::kDouble, CType::kInt16}) CrossCheck(b.table, ct);
      auto e = Export(b.table, Format::kA2l);
      ASSERT_TRUE(e.ok());
      auto file = ar::ReadA2l(e->bytes);
      ASSERT_TRUE(file.ok()) << file.status();
      EXPECT_NE(file->modules[0].FindCharacteristic(Label(b.table, "id_a")), nullptr) << Label(b.table, "id_a");
    }
    EXPECT_EQ(Label((*axis)[1].table, "id_a"), std::string("FLUXCAL_") + (std::string(kind) == "fw" ? "FW" : "ENVELOPE") +
                                                   "_UDC62P5V_ID_A");
  }
}

// The generating envelope (--generating): the strict reader takes its A2L,
// which matches its C header, CDFX and DCM under labels of its own
// (FLUXCAL_ENVELOPE_GENERATING_*), none of them a motoring label.
TEST(A2lExport, GeneratingEnvelopeCrossChecksUnderItsOwnLabels) {
  TableSpec spec;
  spec.kind = "envelope";
  spec.speed_points = 7;
  spec.envelope_generating = true;
  auto b = BuildExportTable(Twin(), spec, {});
  ASSERT_TRUE(b.ok()) << b.status();
  for (CType ct : {CType::kDouble, CType::kInt16, CType::kInt32, CType::kFloat}) CrossCheck(b->table, ct);
  auto e = Export(b->table, Format::kA2l);
  ASSERT_TRUE(e.ok());
  auto file = ar::ReadA2l(e->bytes);
  ASSERT_TRUE(file.ok()) << file.status();
  const auto& mod = file->modules[0];
  EXPECT_NE(mod.FindCharacteristic("FLUXCAL_ENVELOPE_GENERATING_TORQUE_NM"), nullptr);
  EXPECT_EQ(mod.FindCharacteristic("FLUXCAL_ENVELOPE_TORQUE_NM"), nullptr);
}

// Fixed point: the COMPU_METHODs are RAT_FUNC with the LSB the header
// states; floating: IDENTICAL.
TEST(A2lExport, ConversionsFollowTheRepresentation) {
  const Table t = TwinTable("fw");
  for (CType ct : {CType::kDouble, CType::kInt16}) {
    const Exports e = ExportAll(t, ct);
    auto file = ar::ReadA2l(e.a2l);
    ASSERT_TRUE(file.ok()) << file.status();
    const ar::Module& m = file->modules[0];
    const ar::CompuMethod& current = m.compu_methods.at(m.FindCharacteristic("FLUXCAL_FW_ID_A")->conversion);
    EXPECT_EQ(current.unit, "A");
    if (ct == CType::kDouble) {
      EXPECT_EQ(current.conversion_type, "IDENTICAL");
      continue;
    }
    EXPECT_EQ(current.conversion_type, "RAT_FUNC");
    // The currents reach about i_max = 150 A: full scale 256 A (150 A <=
    // 0.8 x 256 A < 0.8 x 512 A), LSB 256 A / 2^15 = 2^-7 A.
    auto one = current.ToPhysical(1.0);
    ASSERT_TRUE(one.ok());
    EXPECT_EQ(*one, std::ldexp(1.0, -7)) << "LSB of the currents, A";
    EXPECT_EQ(m.FindCharacteristic("FLUXCAL_FW_ID_A")->lower_limit, -256.0);
    EXPECT_EQ(m.FindCharacteristic("FLUXCAL_FW_ID_A")->upper_limit, 256.0 - std::ldexp(1.0, -7));
  }
}

// ------------------------------------------------------------ the reader

// A small description written from the standard's keyword structure (not
// by fluxcal): the reader's values, escapes, comments and conversions.
const char* const kHandWritten = R"(ASAP2_VERSION 1 71
/begin PROJECT P "project"
  /begin HEADER "h" VERSION "1" /end HEADER
  /begin MODULE M "module"
    /begin MOD_COMMON "" BYTE_ORDER MSB_FIRST ALIGNMENT_WORD 2 /end MOD_COMMON
    /begin COMPU_METHOD CM_LIN "linear" LINEAR "%6.2" "V" COEFFS_LINEAR 0.5 -1 /end COMPU_METHOD
    /begin COMPU_METHOD CM_RAT "rational" RAT_FUNC "%6.3" "A" COEFFS 0 4 8 0 0 1 /end COMPU_METHOD
    /begin RECORD_LAYOUT RL_AX AXIS_PTS_X 1 UWORD INDEX_INCR DIRECT /end RECORD_LAYOUT
    /begin RECORD_LAYOUT RL_V FNC_VALUES 1 SWORD ROW_DIR DIRECT /end RECORD_LAYOUT
    /begin AXIS_PTS AX "axis \"x\"" 0x7F00 NO_INPUT_QUANTITY RL_AX 0 CM_LIN 4 -1 1.5e2 /end AXIS_PTS
    /begin CHARACTERISTIC C1 "curve" CURVE 0x7F10 RL_V 0 CM_RAT -10 10
      /begin AXIS_DESCR COM_AXIS NO_INPUT_QUANTITY CM_LIN 4 -1 150 AXIS_PTS_REF AX /end AXIS_DESCR
      SYMBOL_LINK "c1" 0 // a line comment
      /* a block comment
         over two lines */
      READ_ONLY
    /end CHARACTERISTIC
  /end MODULE
/end PROJECT
)";

TEST(A2lReader, ReadsTheStandardsKeywordStructure) {
  auto f = ar::ReadA2l(kHandWritten, "hand.a2l");
  ASSERT_TRUE(f.ok()) << f.status();
  EXPECT_EQ(f->project_name, "P");
  EXPECT_EQ(f->header_version, "1");
  const ar::Module& m = f->modules.at(0);
  EXPECT_EQ(m.byte_order, "MSB_FIRST");
  const ar::AxisPts* ax = m.FindAxisPts("AX");
  ASSERT_NE(ax, nullptr);
  EXPECT_EQ(ax->long_identifier, "axis \"x\"");
  EXPECT_EQ(ax->address, 0x7F00u);
  EXPECT_EQ(ax->upper_limit, 150.0);
  const ar::Characteristic* c = m.FindCharacteristic("C1");
  ASSERT_NE(c, nullptr);
  EXPECT_EQ(c->address, 0x7F10u);
  EXPECT_EQ(c->symbol_link, "c1");
  EXPECT_TRUE(c->read_only);
  ASSERT_EQ(c->axes.size(), 1u);
  EXPECT_EQ(c->axes[0].axis_pts_ref, "AX");
  // LINEAR: p = 0.5 raw - 1; RAT_FUNC: raw = 4 p + 8, so p = (raw - 8) / 4.
  EXPECT_EQ(*m.compu_methods.at("CM_LIN").ToPhysical(4), 1.0);
  EXPECT_EQ(*m.compu_methods.at("CM_RAT").ToPhysical(12), 1.0);
  EXPECT_EQ(m.record_layouts.at("RL_V").fnc_index_mode, "ROW_DIR");
}

// The hand-written description with line `line` (1-based) replaced.
std::string WithLine(int line, const std::string& text) {
  std::vector<std::string> lines = absl::StrSplit(kHandWritten, '\n');
  lines.at(line - 1) = text;
  return absl::StrJoin(lines, "\n");
}

TEST(A2lReader, RejectsMalformedFilesNamingTheLine) {
  struct Case {
    const char* what;
    std::string text;
    int line;         // the line the error must name
    const char* says;
  };
  const std::vector<Case> cases = {
      {"unknown keyword", WithLine(16, "      SPEED_LIMIT 3"), 16, "unknown keyword SPEED_LIMIT"},
      {"keyword twice", WithLine(16, "      READ_ONLY READ_ONLY"), 16, "READ_ONLY given twice"},
      {"/end of another block", WithLine(17, "    /end AXIS_PTS"), 17, "does not close /begin CHARACTERISTIC of line 11"},
      {"/begin never closed", WithLine(18, ""), 19, "/end PROJECT does not close /begin MODULE of line 4"},
      {"enumeration value", WithLine(11, "    /begin CHARACTERISTIC C1 \"curve\" CURVY 0x7F10 RL_V 0 CM_RAT -10 10"), 11,
       "parameter Type: expected one of"},
      {"positional parameter missing",
       WithLine(11, "    /begin CHARACTERISTIC C1 \"curve\" CURVE 0x7F10 RL_V 0 CM_RAT -10"), 12,
       "parameter UpperLimit: expected a number, got /begin"},
      {"integer expected", WithLine(10, "    /begin AXIS_PTS AX \"a\" 0x7F00 NO_INPUT_QUANTITY RL_AX 0 CM_LIN 4.5 -1 150 /end AXIS_PTS"),
       10, "parameter MaxAxisPoints: expected an integer"},
      {"block not allowed here", WithLine(16, "      /begin MOD_COMMON \"\" /end MOD_COMMON"), 16,
       "/begin MOD_COMMON is not allowed in /begin CHARACTERISTIC"},
      {"unknown block", WithLine(16, "      /begin IF_DATA XCP /end IF_DATA"), 16, "not a block this reader knows"},
      {"comment not closed", WithLine(15, "         still inside the comment"), 14, "comment /* not closed"},
      {"string not closed", WithLine(11, "    /begin CHARACTERISTIC C1 \"curve CURVE 0x7F10 RL_V 0 CM_RAT -10 10"), 11,
       "string not closed"},
      {"malformed number", WithLine(11, "    /begin CHARACTERISTIC C1 \"curve\" CURVE 0x7G10 RL_V 0 CM_RAT -10 10"), 11,
       "malformed number '0x7G10'"},
      {"stray character", WithLine(16, "      READ_ONLY ;"), 16, "unexpected character ';'"},
      {"deposit not defined", WithLine(11, "    /begin CHARACTERISTIC C1 \"curve\" CURVE 0x7F10 RL_W 0 CM_RAT -10 10"), 11,
       "Deposit RL_W is not a RECORD_LAYOUT"},
      {"conversion not defined", WithLine(11, "    /begin CHARACTERISTIC C1 \"curve\" CURVE 0x7F10 RL_V 0 CM_X -10 10"), 11,
       "Conversion CM_X is not a COMPU_METHOD"},
      {"axis points disagree",
       WithLine(12, "      /begin AXIS_DESCR COM_AXIS NO_INPUT_QUANTITY CM_LIN 5 -1 150 AXIS_PTS_REF AX /end AXIS_DESCR"),
       12, "MaxAxisPoints 5, its AXIS_PTS AX has 4"},
      {"COM_AXIS without its AXIS_PTS",
       WithLine(12, "      /begin AXIS_DESCR COM_AXIS NO_INPUT_QUANTITY CM_LIN 4 -1 150 /end AXIS_DESCR"), 12,
       "COM_AXIS without AXIS_PTS_REF"},
      {"a CURVE without its axis", WithLine(12, ""), 11, "CURVE with 0 AXIS_DESCR, expected 1"},
  };
  for (const Case& c : cases) {
    auto f = ar::ReadA2l(c.text, "bad.a2l");
    ASSERT_FALSE(f.ok()) << c.what << ": accepted";
    const std::string msg(f.status().message());
    EXPECT_TRUE(absl::StartsWith(msg, absl::StrCat("bad.a2l:", c.line, ": ")))
        << c.what << ": expected line " << c.line << ", got: " << msg;
    EXPECT_TRUE(absl::StrContains(msg, c.says)) << c.what << ": " << msg;
  }
}

// A fluxcal export with one line removed is refused at that line: the
// reader checks the real files, not only the hand-written one.
TEST(A2lReader, RejectsADamagedExportAtTheDamagedLine) {
  for (const char* kind : {"mtpa", "fw"}) {
    auto e = Export(TwinTable(kind), Format::kA2l);
    ASSERT_TRUE(e.ok());
    ASSERT_TRUE(ar::ReadA2l(e->bytes).ok());
    std::vector<std::string> lines = absl::StrSplit(e->bytes, '\n');
    int removed = 0;
    for (size_t k = 0; k < lines.size(); ++k) {
      if (absl::StrContains(lines[k], "/end AXIS_DESCR")) {
        lines.erase(lines.begin() + k);
        removed = static_cast<int>(k) + 1;
        break;
      }
    }
    ASSERT_GT(removed, 0);
    auto bad = ar::ReadA2l(absl::StrJoin(lines, "\n"), "cut.a2l");
    ASSERT_FALSE(bad.ok()) << kind;
    EXPECT_TRUE(absl::StartsWith(bad.status().message(), absl::StrCat("cut.a2l:", removed, ": ")))
        << kind << ": the line after the removed /end AXIS_DESCR is " << removed << ": " << bad.status();
  }
}

// -------------------------------------------------------- fixed point

TEST(FixedPoint, FullScaleIsThePowerOfTwoWithHeadroom) {
  EXPECT_EQ(FullScale(150.0), 256.0);   // 150 / 0.8 = 187.5
  EXPECT_EQ(FullScale(204.8), 256.0);   // exactly 0.8 x 256
  EXPECT_EQ(FullScale(204.81), 512.0);
  EXPECT_EQ(FullScale(6000.0), 8192.0);
  EXPECT_EQ(FullScale(0.05), 0.0625);
  EXPECT_EQ(FullScale(0.0), 1.0);
  const Table t = TwinTable("fw");
  for (CType ct : {CType::kInt16, CType::kInt32}) {
    for (const QuantityScale& q : QuantityScales(t, ct)) {
      // Every value of the quantity: its axes and outputs, its scalars.
      double max_abs = 0;
      for (const auto& name : q.arrays) {
        for (const auto& a : t.axes) {
          if (a.name == name) for (double v : a.values) max_abs = std::max(max_abs, std::abs(v));
        }
        for (const auto& o : t.outputs) {
          if (o.name == name) for (double v : o.values) max_abs = std::max(max_abs, std::abs(v));
        }
      }
      for (const Scalar& s : Scalars(t)) {
        if (s.unit == q.unit) max_abs = std::max(max_abs, std::abs(s.value));
      }
      EXPECT_LE(max_abs, kFixedPointFill * q.full_scale) << q.unit;
      EXPECT_GT(max_abs, kFixedPointFill * q.full_scale / 2) << q.unit << ": the smallest such power of two";
      EXPECT_EQ(q.lsb, std::ldexp(q.full_scale, -(FixedPointBits(ct) - 1))) << q.unit;
      int exponent;
      EXPECT_EQ(std::frexp(q.lsb, &exponent), 0.5) << q.unit << ": LSB " << q.lsb << " is not a power of two";
      EXPECT_EQ(q.offset, 0.0);
    }
  }
}

TEST(FixedPoint, RoundTripErrorAtMostHalfAnLsb) {
  std::mt19937_64 rng(25);
  for (int bits : {16, 32}) {
    QuantityScale q;
    q.unit = "A";
    q.bits = bits;
    q.full_scale = 256;
    q.lsb = std::ldexp(256.0, -(bits - 1));
    q.min_value = -256;
    q.max_value = 256 - q.lsb;
    std::uniform_real_distribution<double> u(-250, 250);
    std::vector<double> v;
    for (int k = 0; k < 2000; ++k) v.push_back(u(rng));
    // Ties round half away from zero; the ends of the range are representable.
    v.insert(v.end(), {2.5 * q.lsb, -2.5 * q.lsb, 0.0, q.min_value, q.max_value});
    auto raw = Quantize(v, q, "test");
    ASSERT_TRUE(raw.ok()) << raw.status();
    double worst = 0;
    for (size_t k = 0; k < v.size(); ++k) worst = std::max(worst, std::abs((*raw)[k] * q.lsb - v[k]));
    EXPECT_LE(worst, 0.5 * q.lsb) << bits << " bits: worst round-trip error " << worst << " A, LSB " << q.lsb << " A";
    EXPECT_GT(worst, 0.4 * q.lsb) << "the sample should reach about LSB/2";
    const size_t n = v.size();
    EXPECT_EQ((*raw)[n - 5], 3);
    EXPECT_EQ((*raw)[n - 4], -3);
    EXPECT_EQ((*raw)[n - 2], -(int64_t{1} << (bits - 1)));
    EXPECT_EQ((*raw)[n - 1], (int64_t{1} << (bits - 1)) - 1);
  }
}

TEST(FixedPoint, SaturationIsRefusedNotClipped) {
  QuantityScale q;
  q.unit = "A";
  q.bits = 16;
  q.full_scale = 1;
  q.lsb = std::ldexp(1.0, -15);
  q.min_value = -1;
  q.max_value = 1 - q.lsb;
  auto r = Quantize({0.5, 1.0}, q, "table array 'id_a'");
  ASSERT_EQ(r.status().code(), absl::StatusCode::kOutOfRange) << r.status();
  EXPECT_TRUE(absl::StrContains(r.status().message(), "table array 'id_a'[1]: 1 A does not fit")) << r.status();
  EXPECT_TRUE(absl::StrContains(r.status().message(), "refused rather than saturated")) << r.status();
  // Half an LSB above the top rounds up out of range: refused too.
  EXPECT_FALSE(Quantize({q.max_value + 0.5 * q.lsb}, q, "x").ok());
  EXPECT_TRUE(Quantize({q.max_value + 0.49 * q.lsb, -1.0}, q, "x").ok());
  q.bits = 0;
  EXPECT_EQ(Quantize({0.5}, q, "x").status().code(), absl::StatusCode::kInvalidArgument);
}

// The fixed-point header compiles in strict C99 with conversion warnings
// as errors, and raw * <NAME>_LSB gives the table within half an LSB.
TEST(FixedPoint, HeaderCompilesAndCarriesTheValuesWithinHalfAnLsb) {
  if (std::system("cc --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "no C compiler (cc)";
  const Table t = TwinTable("fw");
  for (CType ct : {CType::kInt16, CType::kInt32}) {
    ExportOptions opt;
    opt.ctype = ct;
    auto e = Export(t, Format::kCHeader, opt);
    ASSERT_TRUE(e.ok()) << e.status();
    EXPECT_EQ(e->bytes.find("double"), std::string::npos) << "no double array in a fixed-point header";
    EXPECT_EQ(e->fixed_point.size(), 3u) << "torque, speed, current";
    std::string prog = "#include <stdio.h>\n#include \"table.h\"\nint main(void) {\n  int k;\n";
    std::vector<std::pair<double, double>> want;   // value, LSB
    ForEachArray(t, [&](const std::string& name, const std::vector<double>& v) {
      const std::string up = absl::AsciiStrToUpper(name);
      prog += "  for (k = 0; k < FLUXCAL_FW_" + up + "_LEN; ++k) printf(\"%.17g\\n\", (double)fluxcal_fw_" + name +
              "[k] * FLUXCAL_FW_" + up + "_LSB);\n";
      for (double x : v) want.push_back({x, ScaleOf(e->fixed_point, name)->lsb});
    });
    prog += "  return 0;\n}\n";
    std::string printed;
    ASSERT_NO_FATAL_FAILURE(BuildAndRunC99(std::string("fluxcal_c_") + CTypeName(ct), {{"table.h", e->bytes}}, prog,
                                           "-Wconversion",
                                           absl::StrCat("compiling the ", CTypeName(ct), " header failed"), &printed));
    std::istringstream in(printed);
    for (const auto& [x, lsb] : want) {
      double got;
      ASSERT_TRUE(in >> got);
      EXPECT_LE(std::abs(got - x), 0.5 * lsb) << "value " << x << ", from the header " << got << ", LSB " << lsb;
    }
  }
}

TEST(FixedPoint, CTypeAndFormatNames) {
  for (const char* n : {"double", "float", "int16", "int32"}) {
    auto ct = ParseCType(n);
    ASSERT_TRUE(ct.ok()) << n;
    EXPECT_STREQ(CTypeName(*ct), n);
  }
  auto bad = ParseCType("int8");
  ASSERT_FALSE(bad.ok());
  EXPECT_TRUE(absl::StrContains(bad.status().message(), "flag --ctype")) << bad.status();
  auto a2l = ParseFormat("a2l");
  ASSERT_TRUE(a2l.ok());
  EXPECT_EQ(*a2l, Format::kA2l);
  EXPECT_TRUE(absl::StrContains(ParseFormat("asap").status().message(), "a2l"));
  // The other formats write decimals whatever the ctype: no fixed point.
  auto csv = Export(TwinTable("mtpa"), Format::kCsv, {CType::kInt16});
  ASSERT_TRUE(csv.ok());
  EXPECT_TRUE(csv->fixed_point.empty());
}

}  // namespace
}  // namespace fluxcal::tables
