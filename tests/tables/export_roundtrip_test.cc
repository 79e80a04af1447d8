// Every export format read back by its own small parser (CSV, JSON, DCM,
// CDFX with tinyxml2, the C header by pattern), and the five readings
// compared: the same axes in the same order, values, flags, scalars (limits,
// machine constants), provenance, verdict and release state, and payload
// checksums. Also: the file checksum fluxcal reports is `sha256sum FILE`,
// the CDFX validates against the subset DTD in this folder, the float C
// header compiles and carries the values, and MTPV / current limits stay in
// the measured region unless extrapolation is asked for.
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <regex>
#include <set>
#include <sstream>

#include "absl/strings/ascii.h"
#include "absl/strings/match.h"
#include "absl/strings/numbers.h"
#include "absl/strings/str_format.h"
#include "absl/strings/str_split.h"
#include "absl/strings/strip.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "simulation/twin.h"
#include "io/sha256.h"
#include "tables/tables.h"
#include "tinyxml2.h"

namespace fluxcal::tables {
namespace {

// What a reader gets out of one exported file.
struct Parsed {
  std::map<std::string, double> scalars;
  std::map<std::string, std::string> text;
  std::vector<std::string> axis_names;
  std::vector<std::vector<double>> axes;
  std::map<std::string, std::vector<double>> arrays;   // outputs and flags, X (first axis) slowest
  std::string payload_crc32, payload_sha256;
};

const std::set<std::string> kTextKeys = {"serial", "model", "created_utc", "fluxcal_version", "verdict",
                                         "release_state"};

// "FLUXCAL_FW_ID_A" -> "id_a".
std::string Local(const Table& t, const std::string& ident) {
  const std::string prefix = absl::AsciiStrToLower(absl::StrCat("fluxcal_", t.kind, "_"));
  std::string s = absl::AsciiStrToLower(ident);
  return absl::StartsWith(s, prefix) ? s.substr(prefix.size()) : s;
}

double ToD(std::string s) {
  s = std::string(absl::StripSuffix(absl::StripAsciiWhitespace(s), "f"));
  double v;
  EXPECT_TRUE(absl::SimpleAtod(s, &v)) << "not a number: '" << s << "'";
  return v;
}

std::vector<double> Numbers(const std::string& s) {
  std::vector<double> v;
  for (auto tok : absl::StrSplit(s, absl::ByAnyChar(" ,\n\t"), absl::SkipWhitespace())) v.push_back(ToD(std::string(tok)));
  return v;
}

// "X = torque_nm (first axis), Y = speed_rpm ..." -> {torque_nm, speed_rpm}.
std::vector<std::string> AxisNames(const std::string& order) {
  std::vector<std::string> out;
  for (const char* key : {"X = ", "Y = "}) {
    const size_t p = order.find(key);
    if (p == std::string::npos) continue;
    const size_t b = p + 4, e = order.find(' ', b);
    out.push_back(order.substr(b, e - b));
  }
  return out;
}

Parsed Expected(const Table& t) {
  Parsed p;
  for (const auto& s : Scalars(t)) p.scalars[s.name] = s.value;
  for (const auto& [k, v] : TextFields(t)) p.text[k] = v;
  for (const auto& a : t.axes) { p.axis_names.push_back(a.name); p.axes.push_back(a.values); }
  for (const auto& o : t.outputs) p.arrays[o.name] = o.values;
  for (const auto& [name, v] : Flags(t)) p.arrays[name] = std::vector<double>(v->begin(), v->end());
  p.payload_crc32 = absl::StrFormat("%08x", t.crc32);
  p.payload_sha256 = t.sha256;
  return p;
}

Parsed ParseCsv(const std::string& bytes) {
  Parsed p;
  std::istringstream in(bytes);
  std::string line;
  std::vector<std::string> cols;
  std::vector<std::vector<double>> rows;
  while (std::getline(in, line)) {
    if (absl::StartsWith(line, "# ")) {
      const size_t c = line.find(": ");
      if (c == std::string::npos) continue;
      const std::string key = line.substr(2, c - 2), rest = line.substr(c + 2);
      if (kTextKeys.count(key)) p.text[key] = rest;
      else if (key == "axis_order") p.axis_names = AxisNames(rest);
      else if (key == "payload_crc32") p.payload_crc32 = rest.substr(0, rest.find(' '));
      else if (key == "payload_sha256") p.payload_sha256 = rest.substr(0, rest.find(' '));
      else p.scalars[key] = ToD(rest.substr(0, rest.find(' ')));
    } else if (cols.empty()) {
      cols = absl::StrSplit(line, ',');
    } else if (!line.empty()) {
      rows.push_back(Numbers(line));
    }
  }
  const size_t na = p.axis_names.size();
  if (na == 0 || rows.empty()) return p;
  std::vector<double> x;
  for (const auto& r : rows) if (x.empty() || r[0] != x.back()) x.push_back(r[0]);
  p.axes.push_back(x);
  if (na == 2) {
    std::vector<double> y;
    for (size_t k = 0; k < rows.size() / x.size(); ++k) y.push_back(rows[k][1]);
    p.axes.push_back(y);
  }
  for (size_t c = na; c < cols.size(); ++c) {
    for (const auto& r : rows) p.arrays[cols[c]].push_back(r[c]);
  }
  return p;
}

Parsed ParseJson(const std::string& bytes) {
  Parsed p;
  const auto j = nlohmann::json::parse(bytes);
  for (const auto& k : kTextKeys) p.text[k] = j.at(k).get<std::string>();
  for (const auto& [k, v] : j.at("scalars").items()) p.scalars[k] = v.at("value").get<double>();
  p.scalars["calibration_version"] = j.at("calibration_version").get<double>();
  for (const auto& a : j.at("axes")) {
    p.axis_names.push_back(a.at("name"));
    p.axes.push_back(a.at("values").get<std::vector<double>>());
  }
  for (const auto& o : j.at("outputs")) p.arrays[o.at("name")] = o.at("values").get<std::vector<double>>();
  for (const char* f : {"clamped", "extrapolated", "by_symmetry", "not_positive_definite"}) {
    p.arrays[f] = j.at(f).get<std::vector<double>>();
  }
  p.payload_crc32 = j.at("payload_crc32");
  p.payload_sha256 = j.at("payload_sha256");
  return p;
}

// DCM 2.0: '*' comments, FESTWERT / KENNLINIE / KENNFELD blocks up to END.
Parsed ParseDcm(const Table& t, const std::string& bytes) {
  Parsed p;
  std::istringstream in(bytes);
  std::string line, block, name;
  std::vector<double> stx, sty;
  std::vector<std::vector<double>> wert;   // one entry per WERT run (per ST/Y for a map)
  bool first_table = true;
  while (std::getline(in, line)) {
    if (absl::StartsWith(line, "* ")) {
      const size_t c = line.find(": ");
      if (c == std::string::npos) continue;
      const std::string key = line.substr(2, c - 2), rest = line.substr(c + 2);
      if (kTextKeys.count(key)) p.text[key] = rest;
      if (key == "payload_crc32") {
        p.payload_crc32 = rest.substr(0, rest.find(','));
        const size_t s = rest.find("payload_sha256: ");
        p.payload_sha256 = rest.substr(s + 16, 64);
      }
      continue;
    }
    std::istringstream ls(line);
    std::string key;
    ls >> key;
    if (key == "FESTWERT" || key == "KENNLINIE" || key == "KENNFELD") {
      block = key;
      ls >> name;
      stx.clear(); sty.clear(); wert.clear();
    } else if (key == "ST/X") {
      double v; while (ls >> v) stx.push_back(v);
    } else if (key == "ST/Y") {
      double v; ls >> v; sty.push_back(v);
      wert.emplace_back();
    } else if (key == "WERT") {
      if (wert.empty()) wert.emplace_back();
      double v; while (ls >> v) wert.back().push_back(v);
    } else if (key == "END") {
      const std::string n = Local(t, name);
      if (block == "FESTWERT") {
        p.scalars[n] = wert.at(0).at(0);
      } else if (block == "KENNLINIE") {
        p.arrays[n] = wert.at(0);
        if (first_table) p.axes = {stx};
      } else {
        // KENNFELD nx ny: WERT run j holds the values over X at Y = sty[j].
        std::vector<double> flat(stx.size() * sty.size());
        for (size_t j = 0; j < sty.size(); ++j)
          for (size_t i = 0; i < stx.size(); ++i) flat[i * sty.size() + j] = wert.at(j).at(i);
        p.arrays[n] = flat;
        if (first_table) p.axes = {stx, sty};
      }
      if (block != "FESTWERT") first_table = false;
      block.clear();
    }
  }
  return p;
}

// CDF 2.0 through tinyxml2: VALUE / ASCII / CURVE / MAP instances.
Parsed ParseCdfx(const Table& t, const std::string& bytes) {
  Parsed p;
  tinyxml2::XMLDocument doc;
  EXPECT_EQ(doc.Parse(bytes.c_str()), tinyxml2::XML_SUCCESS);
  for (auto* n = doc.FirstChild(); n; n = n->NextSibling()) {
    if (auto* c = n->ToComment()) {
      const std::string s = c->Value();
      const size_t a = s.find("payload_crc32 "), b = s.find("payload_sha256 ");
      if (a != std::string::npos) p.payload_crc32 = s.substr(a + 14, 8);
      if (b != std::string::npos) p.payload_sha256 = s.substr(b + 15, 64);
    }
  }
  auto* tree = doc.FirstChildElement("MSRSW")->FirstChildElement("SW-SYSTEMS")->FirstChildElement("SW-SYSTEM")
                   ->FirstChildElement("SW-INSTANCE-SPEC")->FirstChildElement("SW-INSTANCE-TREE");
  bool first_table = true;
  for (auto* inst = tree->FirstChildElement("SW-INSTANCE"); inst; inst = inst->NextSiblingElement("SW-INSTANCE")) {
    const std::string n = Local(t, inst->FirstChildElement("SHORT-NAME")->GetText());
    const std::string cat = inst->FirstChildElement("CATEGORY")->GetText();
    auto* phys = inst->FirstChildElement("SW-VALUE-CONT")->FirstChildElement("SW-VALUES-PHYS");
    if (cat == "VALUE") {
      p.scalars[n] = std::stod(phys->FirstChildElement("V")->GetText());
    } else if (cat == "ASCII") {
      const char* s = phys->FirstChildElement("VT")->GetText();
      p.text[n] = s ? s : "";
    } else {
      std::vector<double> flat;
      if (cat == "MAP") {
        for (auto* vg = phys->FirstChildElement("VG"); vg; vg = vg->NextSiblingElement("VG"))
          for (auto* v = vg->FirstChildElement("V"); v; v = v->NextSiblingElement("V")) flat.push_back(std::stod(v->GetText()));
      } else {
        for (auto* v = phys->FirstChildElement("V"); v; v = v->NextSiblingElement("V")) flat.push_back(std::stod(v->GetText()));
      }
      p.arrays[n] = flat;
      if (first_table) {
        for (auto* ac = inst->FirstChildElement("SW-AXIS-CONTS")->FirstChildElement("SW-AXIS-CONT"); ac;
             ac = ac->NextSiblingElement("SW-AXIS-CONT")) {
          std::vector<double> ax;
          for (auto* v = ac->FirstChildElement("SW-VALUES-PHYS")->FirstChildElement("V"); v; v = v->NextSiblingElement("V"))
            ax.push_back(std::stod(v->GetText()));
          p.axes.push_back(ax);
        }
        first_table = false;
      }
    }
  }
  return p;
}

// The C header by pattern: #define scalars, char[] text, arrays, checksums.
Parsed ParseCHeader(const Table& t, const std::string& bytes) {
  Parsed p;
  std::smatch m;
  const std::regex order(R"re(\* axis order: ([^\n]*))re");
  if (std::regex_search(bytes, m, order)) p.axis_names = AxisNames(m[1]);
  const std::regex def(R"re(#define (FLUXCAL_\w+) ([^\s]+)\n)re");
  for (auto it = std::sregex_iterator(bytes.begin(), bytes.end(), def); it != std::sregex_iterator(); ++it) {
    const std::string n = (*it)[1];
    if (absl::EndsWith(n, "_LEN")) continue;
    p.scalars[Local(t, n)] = ToD((*it)[2]);
  }
  const std::regex str(R"re(static const char (\w+)\[\] = "((?:[^"\\]|\\.)*)";)re");
  for (auto it = std::sregex_iterator(bytes.begin(), bytes.end(), str); it != std::sregex_iterator(); ++it) {
    std::string v = (*it)[2];
    v = std::regex_replace(v, std::regex(R"re(\\(.))re"), "$1");
    const std::string n = Local(t, (*it)[1]);
    if (n == "payload_sha256") p.payload_sha256 = v; else p.text[n] = v;
  }
  const std::regex crc(R"re(static const uint32_t \w+_payload_crc32 = 0x([0-9a-f]{8})u;)re");
  if (std::regex_search(bytes, m, crc)) p.payload_crc32 = m[1];
  const std::regex arr(R"re(static const (?:double|float|uint8_t) (\w+)\[(\d+)\] = \{([^}]*)\})re");
  std::map<std::string, std::vector<double>> all;
  for (auto it = std::sregex_iterator(bytes.begin(), bytes.end(), arr); it != std::sregex_iterator(); ++it) {
    all[Local(t, (*it)[1])] = Numbers((*it)[3]);
  }
  for (const auto& a : p.axis_names) { p.axes.push_back(all[a]); all.erase(a); }
  p.arrays = all;
  return p;
}

// A field-weakening map with clamped cells, a measured limit, and a known
// verdict and release state (as the service writes them).
Table Fw() {
  static const sim::AnalyticMotor m{[] { sim::MotorParams p; p.sat.g_cross_h = 3e-5; return p; }()};
  TableSpec spec;
  spec.kind = "fw";
  spec.points = 5;
  spec.speed_points = 4;
  spec.speed_max_rpm = 6000;
  spec.serial = "IPM-T-1";
  spec.calibration_version = 3;
  spec.model = "analytic";
  spec.verdict = "pass";
  spec.release_state = kReleased;
  spec.measured_current_limit_a = 150;
  auto t = BuildTable(m, MachineLimits{}, spec);
  EXPECT_TRUE(t.ok()) << t.status();
  return *t;
}

// An MTPV curve beyond the measured region, on request: extrapolated cells.
Table MtpvExtrapolated() {
  static const sim::AnalyticMotor m{[] { sim::MotorParams p; p.sat.g_cross_h = 3e-5; return p; }()};
  TableSpec spec;
  spec.kind = "mtpv";
  spec.points = 7;
  spec.serial = "IPM-T-2";
  spec.model = "analytic";
  spec.measured_current_limit_a = 150;
  spec.allow_extrapolation = true;
  auto t = BuildTable(m, MachineLimits{}, spec);
  EXPECT_TRUE(t.ok()) << t.status();
  return *t;
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
  for (const Table& t : {Fw(), MtpvExtrapolated()}) {
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
  for (const char* block : {"FESTWERT FLUXCAL_FW_PSI_PM_WB\n", "FESTWERT FLUXCAL_FW_RS_OHM\n",
                            "FESTWERT FLUXCAL_FW_POLE_PAIRS\n", "FESTWERT FLUXCAL_FW_I_MAX_A\n",
                            "FESTWERT FLUXCAL_FW_U_MAX_V\n", "KENNFELD FLUXCAL_FW_CLAMPED 5 4\n"}) {
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
  for (const Table& t : {Fw(), MtpvExtrapolated()}) {
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
  const std::string dir = ::testing::TempDir() + "/fluxcal_c_float";
  ASSERT_EQ(std::system(("mkdir -p " + dir).c_str()), 0);
  { std::ofstream(dir + "/table.h") << e->bytes; }
  std::string prog = "#include <stdio.h>\n#include \"table.h\"\nint main(void) {\n  int k;\n  float s = FLUXCAL_FW_I_MAX_A;\n";
  std::vector<double> want;
  auto print = [&](const std::string& name, const std::vector<double>& v) {
    prog += "  for (k = 0; k < FLUXCAL_FW_" + absl::AsciiStrToUpper(name) + "_LEN; ++k) printf(\"%.9g\\n\", (double)fluxcal_fw_" +
            name + "[k]);\n";
    for (double x : v) want.push_back(static_cast<float>(x));
  };
  for (const auto& a : t.axes) print(a.name, a.values);
  for (const auto& o : t.outputs) print(o.name, o.values);
  prog += "  printf(\"%.9g\\n\", (double)s);\n  return 0;\n}\n";
  want.push_back(static_cast<float>(t.limits.i_max_a));
  { std::ofstream(dir + "/main.c") << prog; }
  const std::string cmd = "cd " + dir + " && cc -std=c99 -pedantic -Wall -Wextra -Werror -Wconversion -Wdouble-promotion "
                          "main.c -o main > build.log 2>&1 && ./main > out.txt";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << "compiling the float header failed; see " << dir << "/build.log";
  std::ifstream in(dir + "/out.txt");
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
  const sim::AnalyticMotor m{[] { sim::MotorParams p; p.sat.g_cross_h = 3e-5; return p; }()};
  TableSpec spec;
  spec.kind = "mtpv";
  spec.points = 9;
  spec.measured_current_limit_a = 150;
  MachineLimits lim;   // i_max 150 A
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

  MachineLimits big;
  big.i_max_a = 200;
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
  MachineLimits small;
  small.i_max_a = 10;
  TableSpec s2;
  s2.kind = "mtpv";
  s2.points = 5;
  s2.measured_current_limit_a = 10;
  auto none = BuildTable(m, small, s2);
  EXPECT_EQ(none.status().code(), absl::StatusCode::kFailedPrecondition) << none.status();
}

}  // namespace
}  // namespace fluxcal::tables
