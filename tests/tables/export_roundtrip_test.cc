// Every export format read back by its own small parser (export_readers.h:
// CSV, JSON, DCM, CDFX with tinyxml2, the C header by pattern), and the five readings
// compared: the same axes in the same order, values, flags, scalars (limits,
// machine constants), provenance, verdict and release state, and payload
// checksums. Also: the file checksum fluxcal reports is `sha256sum FILE`,
// the CDFX validates against the subset DTD in this folder, the float C
// header compiles and carries the values, and MTPV / current limits stay in
// the measured region unless extrapolation is asked for.
#include <cstdio>
#include <cstdlib>
#include <fstream>

#include "absl/strings/ascii.h"
#include "absl/strings/str_format.h"
#include "gtest/gtest.h"
#include "simulation/twin.h"
#include "io/sha256.h"
#include "tables/tables.h"
#include "tests/tables/export_readers.h"
#include "tests/tables/c_unit.h"
#include "tests/tables/twin_limits.h"

namespace fluxcal::tables {
namespace {

using readers::Expected;
using readers::Parsed;
using readers::ParseCdfx;
using readers::ParseCHeader;
using readers::ParseCsv;
using readers::ParseDcm;
using readers::ParseJson;

// The saturated twin's table (a test failure when it cannot be built).
Table Built(const TableSpec& spec, double i_max_a = 150) {
  auto t = BuildTable(SaturatedTwin(), TwinLimits(i_max_a), spec);
  EXPECT_TRUE(t.ok()) << t.status();
  return *t;
}

// A table of the analytic model measured up to 150 A, computed beyond that
// on request (extrapolated cells).
TableSpec ExtrapolatedSpec(const std::string& kind, const std::string& serial) {
  TableSpec spec;
  spec.kind = kind;
  spec.serial = serial;
  spec.model = "analytic";
  spec.measured_current_limit_a = 150;
  spec.allow_extrapolation = true;
  return spec;
}

// A field-weakening map with clamped cells, a measured limit, and a known
// verdict and release state (as the service writes them).
Table Fw() {
  TableSpec spec = SmallLabelledSpec("fw", 6000);
  spec.verdict = "pass";
  spec.release_state = kReleased;
  spec.measured_current_limit_a = 150;
  return Built(spec);
}

// An MTPV curve beyond the measured region, on request: extrapolated cells.
Table MtpvExtrapolated() {
  TableSpec spec = ExtrapolatedSpec("mtpv", "IPM-T-2");
  spec.points = 7;
  return Built(spec);
}

// The envelope of one Udc of an axis (labels tagged with it), at a magnet
// temperature, beyond the measured current limit on request: every
// format's readers meet the tag, the magnet scalars and extrapolated cells.
Table EnvelopeTagged() {
  TableSpec spec = ExtrapolatedSpec("envelope", "IPM-T-3");
  spec.speed_points = 9;
  spec.speed_max_rpm = 8000;
  spec.label_tag = UdcTag(50);
  spec.magnet_temperature = MagnetTemperature{-0.0011, 25, 80};
  return Built(spec, 180);
}

void ExpectSame(const Parsed& want, const Parsed& got, const std::string& what) {
  EXPECT_EQ(got.scalars, want.scalars) << what << ": scalars (limits, machine constants)";
  EXPECT_EQ(got.text, want.text) << what << ": provenance, verdict, release state";
  EXPECT_EQ(got.axes, want.axes) << what << ": axes, in the order X (first axis), Y";
  EXPECT_EQ(got.arrays, want.arrays) << what << ": outputs and flags, X slowest";
  EXPECT_EQ(got.payload_crc32, want.payload_crc32) << what;
  EXPECT_EQ(got.payload_sha256, want.payload_sha256) << what;
}

TEST(ExportRoundTrip, AllFiveFormatsCarryTheSameTable) {
  for (const Table& t : {Fw(), MtpvExtrapolated(), EnvelopeTagged()}) {
    const Parsed want = Expected(t);
    int flagged = 0;
    for (double f : want.arrays.at("clamped")) flagged += f != 0;
    for (double f : want.arrays.at("extrapolated")) flagged += f != 0;
    EXPECT_GT(flagged, 0) << t.kind << ": the fixture should exercise the flags";
    for (Format f : {Format::kCsv, Format::kJson, Format::kDcm, Format::kCdfx, Format::kCHeader}) {
      auto e = Export(t, f);
      ASSERT_TRUE(e.ok()) << e.status();
      Parsed got;
      std::string what = t.kind;
      switch (f) {
        case Format::kCsv: got = ParseCsv(e->bytes); what += " csv"; break;
        case Format::kJson: got = ParseJson(e->bytes); what += " json"; break;
        case Format::kDcm: got = ParseDcm(t, e->bytes); what += " dcm"; break;
        case Format::kCdfx: got = ParseCdfx(t, e->bytes); what += " cdfx"; break;
        case Format::kCHeader: got = ParseCHeader(t, e->bytes); what += " h"; break;
        case Format::kA2l: break;   // describes the C header, holds no values: a2l_test.cc
      }
      ExpectSame(want, got, what);
    }
  }
}

TEST(ExportRoundTrip, LimitsVerdictAndReleaseAreInTheFiles) {
  const Table t = Fw();
  const Parsed p = Expected(t);
  EXPECT_EQ(p.text.at("verdict"), "pass");
  EXPECT_EQ(p.text.at("release_state"), "released");
  EXPECT_EQ(p.text.at("fluxcal_version"), FluxcalVersion());
  EXPECT_DOUBLE_EQ(p.scalars.at("i_max_a"), 150.0);
  EXPECT_DOUBLE_EQ(p.scalars.at("udc_v"), 50.0);
  EXPECT_DOUBLE_EQ(p.scalars.at("u_max_v"), 50.0 / std::sqrt(3.0));
  EXPECT_DOUBLE_EQ(p.scalars.at("speed_max_rpm"), 6000.0);
  EXPECT_DOUBLE_EQ(p.scalars.at("pole_pairs"), 4.0);
  EXPECT_GT(p.scalars.at("psi_pm_wb"), 0.0);
  auto dcm = Export(t, Format::kDcm);
  ASSERT_TRUE(dcm.ok());
  // The map's shape: round breakpoints, at most 5 torques and 4 speeds.
  const size_t nt = t.axes[0].values.size(), ns = t.axes[1].values.size();
  EXPECT_LE(nt, 5u);
  EXPECT_LE(ns, 4u);
  const std::string map_block = "KENNFELD FLUXCAL_FW_CLAMPED " + std::to_string(nt) + " " + std::to_string(ns) + "\n";
  for (const std::string& block : {std::string("FESTWERT FLUXCAL_FW_PSI_PM_WB\n"), std::string("FESTWERT FLUXCAL_FW_RS_OHM\n"),
                                   std::string("FESTWERT FLUXCAL_FW_POLE_PAIRS\n"), std::string("FESTWERT FLUXCAL_FW_I_MAX_A\n"),
                                   std::string("FESTWERT FLUXCAL_FW_U_MAX_V\n"), map_block}) {
    EXPECT_NE(dcm->bytes.find(block), std::string::npos) << block;
  }
}

// What fluxcal reports as the file checksum is the checksum of the bytes
// written: the same as `sha256sum FILE`; the payload checksum differs.
TEST(ExportRoundTrip, FileChecksumIsSha256sumOfTheFile) {
  const bool have_tool = std::system("sha256sum --version > /dev/null 2>&1") == 0;
  const Table t = Fw();
  for (Format f : {Format::kCsv, Format::kJson, Format::kDcm, Format::kCdfx, Format::kCHeader}) {
    auto e = Export(t, f);
    ASSERT_TRUE(e.ok());
    EXPECT_EQ(e->file_sha256, io::Sha256Hex(e->bytes));
    EXPECT_NE(e->file_sha256, e->payload_sha256);
    if (!have_tool) continue;
    const std::string path = ::testing::TempDir() + "/fluxcal_sum_" + std::to_string(static_cast<int>(f));
    { std::ofstream(path, std::ios::binary) << e->bytes; }
    FILE* pipe = popen(("sha256sum " + path).c_str(), "r");
    ASSERT_NE(pipe, nullptr);
    char buf[65] = {};
    ASSERT_EQ(std::fread(buf, 1, 64, pipe), 64u);
    pclose(pipe);
    EXPECT_EQ(std::string(buf), e->file_sha256) << path;
  }
}

TEST(ExportRoundTrip, CdfxValidatesAgainstTheSubsetDtd) {
  if (std::system("xmllint --version > /dev/null 2>&1") != 0) {
    GTEST_SKIP() << "xmllint not installed (libxml2-utils, scripts/install-deps.sh)";
  }
  const std::string dir = ::testing::TempDir();
  int k = 0;
  for (const Table& t : {Fw(), MtpvExtrapolated(), EnvelopeTagged()}) {
    auto e = Export(t, Format::kCdfx);
    ASSERT_TRUE(e.ok());
    const std::string path = dir + "/fluxcal_dtd_" + std::to_string(k++) + ".cdfx";
    { std::ofstream(path) << e->bytes; }
    const std::string cmd = std::string("xmllint --noout --nonet --dtdvalid ") + FLUXCAL_CDF_SUBSET_DTD + " " + path +
                            " > " + path + ".log 2>&1";
    EXPECT_EQ(std::system(cmd.c_str()), 0) << "see " << path << ".log";
  }
  // The check has teeth: a misplaced element fails it.
  auto e = Export(Fw(), Format::kCdfx);
  std::string bad = e->bytes;
  bad.replace(bad.find("<SW-INSTANCE-SPEC>"), 18, "");
  bad.replace(bad.find("</SW-INSTANCE-SPEC>"), 19, "");
  const std::string path = dir + "/fluxcal_dtd_bad.cdfx";
  { std::ofstream(path) << bad; }
  const std::string cmd = std::string("xmllint --noout --nonet --dtdvalid ") + FLUXCAL_CDF_SUBSET_DTD + " " + path +
                          " > /dev/null 2>&1";
  EXPECT_NE(std::system(cmd.c_str()), 0);
}

// --ctype float: float arrays and scalars with 'f' literals, compiled in
// strict C99 with conversion warnings as errors; the values are the table's
// rounded to binary32.
TEST(ExportRoundTrip, FloatCHeaderCompilesAndCarriesRoundedValues) {
  if (std::system("cc --version > /dev/null 2>&1") != 0) GTEST_SKIP() << "no C compiler (cc)";
  const Table t = Fw();
  ExportOptions opt;
  opt.ctype = CType::kFloat;
  auto e = Export(t, Format::kCHeader, opt);
  ASSERT_TRUE(e.ok());
  EXPECT_EQ(e->bytes.find("double"), std::string::npos) << "a float header declares no double";
  std::string prog = "#include <stdio.h>\n#include \"table.h\"\nint main(void) {\n  int k;\n  float s = FLUXCAL_FW_I_MAX_A;\n";
  std::vector<double> want;
  ForEachArray(t, [&](const std::string& name, const std::vector<double>& v) {
    prog += "  for (k = 0; k < FLUXCAL_FW_" + absl::AsciiStrToUpper(name) + "_LEN; ++k) printf(\"%.9g\\n\", (double)fluxcal_fw_" +
            name + "[k]);\n";
    for (double x : v) want.push_back(static_cast<float>(x));
  });
  prog += "  printf(\"%.9g\\n\", (double)s);\n  return 0;\n}\n";
  want.push_back(static_cast<float>(t.limits.i_max_a));
  std::string printed;
  ASSERT_NO_FATAL_FAILURE(BuildAndRunC99("fluxcal_c_float", {{"table.h", e->bytes}}, prog,
                                         "-Wconversion -Wdouble-promotion", "compiling the float header failed",
                                         &printed));
  std::istringstream in(printed);
  for (double x : want) {
    double got;
    ASSERT_TRUE(in >> got);
    EXPECT_EQ(static_cast<float>(got), static_cast<float>(x));
  }
  EXPECT_FALSE(ParseCType("half").ok());
}

// By default a table stays inside the measured region: a current limit
// above the measured one is refused, and the MTPV curve is cut to the fluxes
// whose MTPV point lies inside the current limit; --allow-extrapolation
// computes beyond, with the cells flagged.
TEST(Extrapolation, RefusedByDefaultFlaggedOnRequest) {
  const sim::AnalyticMotor& m = SaturatedTwin();
  TableSpec spec;
  spec.kind = "mtpv";
  spec.points = 9;
  spec.measured_current_limit_a = 150;
  MachineLimits lim = TwinLimits();   // i_max 150 A
  auto inside = BuildTable(m, lim, spec);
  ASSERT_TRUE(inside.ok()) << inside.status();
  for (size_t k = 0; k < inside->clamped.size(); ++k) {
    EXPECT_EQ(inside->clamped[k], 0) << "row " << k;
    EXPECT_EQ(inside->extrapolated[k], 0) << "row " << k;
    EXPECT_LE(std::hypot(inside->outputs[0].values[k], inside->outputs[1].values[k]), 150.0 * (1 + 1e-6)) << "row " << k;
  }
  const Table beyond = MtpvExtrapolated();
  int flagged = 0;
  for (auto f : beyond.extrapolated) flagged += f;
  EXPECT_GT(flagged, 0);
  EXPECT_EQ(beyond.extrapolated, beyond.clamped) << "with i_max = the measured limit both flags coincide";

  MachineLimits big = TwinLimits(200);
  spec.kind = "mtpa";
  auto refused = BuildTable(m, big, spec);
  ASSERT_EQ(refused.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(refused.status().message().find("--i-max-a"), std::string::npos) << refused.status();
  spec.allow_extrapolation = true;
  auto allowed = BuildTable(m, big, spec);
  ASSERT_TRUE(allowed.ok());
  int beyond_meas = 0;
  for (auto f : allowed->extrapolated) beyond_meas += f;
  EXPECT_GT(beyond_meas, 0) << "MTPA rows above 150 A are flagged";

  // A measured region the MTPV curve never enters: no MTPV table by default.
  MachineLimits small = TwinLimits(10);
  TableSpec s2;
  s2.kind = "mtpv";
  s2.points = 5;
  s2.measured_current_limit_a = 10;
  auto none = BuildTable(m, small, s2);
  EXPECT_EQ(none.status().code(), absl::StatusCode::kFailedPrecondition) << none.status();
}

}  // namespace
}  // namespace fluxcal::tables
