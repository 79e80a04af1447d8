// Tests of the flux-map reader/writer: the published map of a real machine
// reads as its 21 x 27 grid, the spellings the field's tools use are
// accepted, every malformed input yields an error naming file, line and
// field, and a written map reads back bit for bit. Then the field's
// conventions (SyR-e's axes, rms and power-invariant scaling, mWb) on maps
// made from the real one, and the plausibility checks that refuse a map in
// the wrong convention with its likely cause.
#include "io/flux_map.h"

#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <random>
#include <sstream>

#include "absl/strings/str_format.h"
#include "gtest/gtest.h"
#include "io/csv.h"

namespace fluxcal::io {
namespace {

namespace fs = std::filesystem;

constexpr double kPi30 = 3.14159265358979323846 / 6;   // 30 degrees

// The published measured map, copied into the repository (data/real).
const std::string kBaldor = std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_fluxmap_measured.csv";

// A 3 x 2 map (id -2, 0, 2; iq 0, 4) in the order given, header first.
std::string SmallMap(const std::string& header = "id_A,iq_A,psi_d_Vs,psi_q_Vs") {
  return header + "\n"
                  "-2,0,0.09,0\n"
                  "-2,4,0.091,0.02\n"
                  "0,0,0.1,0\n"
                  "0,4,0.1001,0.021\n"
                  "2,0,0.11,0\n"
                  "2,4,0.1101,0.022\n";
}

// Parses `text` as "m.csv" and expects an error containing `want`.
void ExpectError(const std::string& text, const std::string& want, FluxMapReadOptions o = {}) {
  auto m = ParseFluxMapCsv(text, "m.csv", o);
  ASSERT_FALSE(m.ok()) << "accepted:\n" << text;
  EXPECT_EQ(m.status().code(), absl::StatusCode::kInvalidArgument);
  EXPECT_NE(std::string(m.status().message()).find(want), std::string::npos)
      << "expected '" << want << "' in: " << m.status().message();
}

TEST(FluxMap, ReadsThePublishedMapOfARealMachine) {
  auto m = ReadFluxMapCsv(kBaldor);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->source, kBaldor);
  ASSERT_EQ(m->id_a.size(), 21u);
  ASSERT_EQ(m->iq_a.size(), 27u);
  EXPECT_EQ(m->size(), 567u);
  EXPECT_EQ(m->Points().size(), 567u);
  EXPECT_EQ(m->id_a.front(), -20.0);
  EXPECT_EQ(m->id_a.back(), 20.0);
  EXPECT_EQ(m->iq_a.front(), -26.0);
  EXPECT_EQ(m->iq_a.back(), 26.0);
  // The file writes the origin as "-0,-0": one axis value 0, not -0.
  EXPECT_EQ(m->id_a[10], 0.0);
  EXPECT_FALSE(std::signbit(m->id_a[10]));
  EXPECT_FALSE(std::signbit(m->iq_a[13]));
  EXPECT_EQ(m->psi_d_wb[10][13], 0.44414573760687304);   // psi_pm, raw
  EXPECT_EQ(m->psi_q_wb[10][13], 4.124226562320374e-06);
  EXPECT_EQ(m->psi_q_wb[0][0], -1.3099196001581734);      // first row: id -20, iq -26

  FluxMapReadOptions sym;
  sym.columns = FluxMapColumns::kSymmetrised;
  auto s = ReadFluxMapCsv(kBaldor, sym);
  ASSERT_TRUE(s.ok()) << s.status();
  EXPECT_EQ(s->psi_q_wb[10][13], 0.0);
  EXPECT_EQ(s->psi_q_wb[0][0], -1.3117042234481113);
}

TEST(FluxMap, AcceptsTheCommonSpellings) {
  for (const char* header : {"id_A,iq_A,psi_d_Vs,psi_q_Vs", "id_a,iq_a,psi_d_wb,psi_q_wb", "Id,Iq,Fd,Fq",
                             "id,iq,fd,fq", "ID_A,IQ_A,PSI_D,PSI_Q", "\"id_A\",\"iq_A\",\"psi_d_Vs\",\"psi_q_Vs\"",
                             "i_d,i_q,psid,psiq", "Fq,Fd,Iq,Id"}) {
    std::string text = SmallMap(header);
    if (std::string(header) == "Fq,Fd,Iq,Id") {
      // Columns in another order: same numbers, rearranged per row.
      text = "Fq,Fd,Iq,Id\n0,0.09,0,-2\n0.02,0.091,4,-2\n0,0.1,0,0\n0.021,0.1001,4,0\n0,0.11,0,2\n0.022,0.1101,4,2\n";
    }
    auto m = ParseFluxMapCsv(text, "m.csv");
    ASSERT_TRUE(m.ok()) << header << ": " << m.status();
    EXPECT_EQ(m->id_a, (std::vector<double>{-2, 0, 2})) << header;
    EXPECT_EQ(m->iq_a, (std::vector<double>{0, 4})) << header;
    EXPECT_EQ(m->psi_d_wb[1][1], 0.1001) << header;
    EXPECT_EQ(m->psi_q_wb[2][1], 0.022) << header;
  }
  // Byte-order mark, comment preamble, CRLF, extra columns (not parsed),
  // nodes in any order, a trailing empty line.
  auto m = ParseFluxMapCsv(
      "\xEF\xBB\xBF# exported by a bench\r\n# units: A, Vs\r\n"
      "note,id_A,iq_A,psi_d_Vs,psi_q_Vs,eq_map_undocumented\r\n"
      "b,2,4,0.1101,0.022,\r\na,-2,0,0.09,0,x\r\nc,0,4,0.1001,0.021,1\r\n"
      "d,-2,4,0.091,0.02,1\r\ne,2,0,0.11,0,1\r\nf,0,0,0.1,0,1\r\n\r\n",
      "m.csv");
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->psi_d_wb[0][1], 0.091);
  EXPECT_EQ(m->psi_d_wb[2][1], 0.1101);
}

TEST(FluxMap, MalformedInputNamesFileLineAndField) {
  // Text in a number, NaN, infinity, empty cell.
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n-2,0,0.09,0\n-2,4,x,0.02\n",
              "m.csv:3: field 'psi_d_Vs': expected a number, got 'x'");
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n-2,0,0.09,0\n-2,4,0.091,nan\n",
              "m.csv:3: field 'psi_q_Vs': expected a finite number, got 'nan'");
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n-2,0,0.09,0\n-2,inf,0.091,0.02\n",
              "m.csv:3: field 'iq_A': expected a finite number, got 'inf'");
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n-2,0,0.09,0\n-2,4,,0.02\n", "m.csv:3: field 'psi_d_Vs': empty cell");
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n-2,0,0.09,0\n-2,4,1e999,0.02\n",
              "m.csv:3: field 'psi_d_Vs': number out of range");
  // Missing and ambiguous columns; symmetrised pair asked for but absent.
  ExpectError("id_A,iq_A,psi_d_Vs\n-2,0,0.09\n", "m.csv:1: field 'psi_q': missing column (accepted, any case: psi_q_Vs, psi_q_Wb, psi_q_mVs, psi_q_mWb, psi_q, psiq, Fq; header has id_A, iq_A, psi_d_Vs)");
  ExpectError("id_A,current_q,psi_d_Vs,psi_q_Vs\n", "m.csv:1: field 'iq': missing column");
  ExpectError("id_A;iq_A;psi_d_Vs;psi_q_Vs\n", "expected comma-separated values");
  ExpectError("id_A,Id,iq_A,psi_d_Vs,psi_q_Vs\n", "m.csv:1: field 'Id': ambiguous: columns 1 ('id_A') and 2");
  FluxMapReadOptions sym;
  sym.columns = FluxMapColumns::kSymmetrised;
  ExpectError(SmallMap(), "m.csv:1: field 'psi_d_sym': missing column", sym);
  // Rows of the wrong width.
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n-2,0,0.09\n", "m.csv:2: field 'psi_q_Vs': missing cell (row has 3, header 4)");
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n-2,0,0.09,0,7\n", "m.csv:2: field 'psi_q_Vs': too many cells");
  // Duplicate node ("-0" and "0" are the same current).
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n-2,0,0.09,0\n-2,4,0.091,0.02\n-2,-0,0.09,0\n",
              "m.csv:4: field 'iq_A': duplicate node (id = -2 A, iq = 0 A), first on line 2");
  // Missing node: line 5 ("0,4,...") removed; the error points at the
  // nearest node of its id row (0, 0) on line 4.
  {
    std::string text = SmallMap();
    const std::string gone = "0,4,0.1001,0.021\n";
    text.erase(text.find(gone), gone.size());
    ExpectError(text,
                "m.csv:4: field 'iq_A': missing node (id = 0 A, iq = 4 A): the map is not a full grid (3 id values x "
                "2 iq values need 6 nodes, the file has 5); nearest node of this id row: iq = 0 A on line 4");
  }
  // A node off its grid by rounding is a missing node, not snapped.
  {
    std::string text = SmallMap();
    text.replace(text.find("2,4,0.1101"), 3, "2,4.000001");
    ExpectError(text, "missing node");
  }
  // Empty input, header only, an empty line inside the data.
  ExpectError("", "m.csv:1: field 'id': empty file, no header");
  ExpectError("# only a comment\n", "m.csv:1: field 'id': empty file, no header");
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n", "m.csv:1: field 'id_A': no data rows after the header");
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n-2,0,0.09,0\n\n-2,4,0.091,0.02\n", "m.csv:3: field 'id_A': empty line");
  // A control byte in a cell is echoed escaped.
  ExpectError("id_A,iq_A,psi_d_Vs,psi_q_Vs\n-2,0,0.09,\x01\n", "got '\\x01'");
}

TEST(FluxMap, BoundedSizeAndMissingFile) {
  std::string big(kMaxFluxMapBytes + 1, '\n');
  ExpectError(big, "m.csv:1: field '(file)': file is 67108865 bytes, more than the 64 MiB");
  auto m = ReadFluxMapCsv("/nonexistent/dir/map.csv");
  ASSERT_FALSE(m.ok());
  EXPECT_EQ(m.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(std::string(m.status().message()).find("/nonexistent/dir/map.csv"), std::string::npos);
}

TEST(FluxMap, WriteReadRoundTripExact) {
  // Values no short decimal represents, of every magnitude a map holds
  // (around a plausible machine's: psi_pm 0.1 Wb, 2 and 3 mH, so that the
  // reader's plausibility checks pass).
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  FluxMap m;
  for (int i = 0; i < 13; ++i) m.id_a.push_back(-150.0 + 12.5 * i + (i == 3 ? 1e-13 : 0.0) + u(rng) * 1e-3);
  for (int j = 0; j < 9; ++j) m.iq_a.push_back(std::ldexp(static_cast<double>(j), -3) * 17.0 / 3.0);
  m.psi_d_wb.assign(13, std::vector<double>(9));
  m.psi_q_wb = m.psi_d_wb;
  for (int i = 0; i < 13; ++i) {
    for (int j = 0; j < 9; ++j) {
      m.psi_d_wb[i][j] = 0.1 + 0.002 * m.id_a[i] * (1 + u(rng) / 30.0);
      m.psi_q_wb[i][j] = 0.003 * m.iq_a[j] * (1 + u(rng) / 30.0) + u(rng) * std::pow(10.0, -(i + j) % 7) * 1e-6;
    }
  }
  m.psi_q_wb[0][0] = 5e-324;   // subnormal
  auto text = FluxMapCsv(m);
  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_EQ(text->rfind("id_A,iq_A,psi_d_Vs,psi_q_Vs\n", 0), 0u);
  // No node at zero current (the id axis is off 0 by its jitter): the axes
  // are given, as a reader of an export must.
  FluxMapReadOptions given;
  given.convention.axes = FluxMapAxes::kFluxcal;
  EXPECT_FALSE(ParseFluxMapCsv(*text, "m.csv").ok());
  auto back = ParseFluxMapCsv(*text, "m.csv", given);
  ASSERT_TRUE(back.ok()) << back.status();
  EXPECT_EQ(back->id_a, m.id_a);
  EXPECT_EQ(back->iq_a, m.iq_a);
  EXPECT_EQ(back->psi_d_wb, m.psi_d_wb);
  EXPECT_EQ(back->psi_q_wb, m.psi_q_wb);

  // Through a file, and the published map through write and read.
  const fs::path dir = fs::temp_directory_path() / ("fluxcal_fluxmap_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  auto baldor = ReadFluxMapCsv(kBaldor);
  ASSERT_TRUE(baldor.ok());
  const std::string path = (dir / "baldor.csv").string();
  ASSERT_TRUE(WriteFluxMapCsv(path, *baldor).ok());
  auto again = ReadFluxMapCsv(path);
  ASSERT_TRUE(again.ok()) << again.status();
  EXPECT_EQ(again->id_a, baldor->id_a);
  EXPECT_EQ(again->iq_a, baldor->iq_a);
  EXPECT_EQ(again->psi_d_wb, baldor->psi_d_wb);
  EXPECT_EQ(again->psi_q_wb, baldor->psi_q_wb);
  fs::remove_all(dir);

  // The writer refuses what is not a map.
  FluxMap bad = m;
  bad.psi_q_wb[2][3] = std::nan("");
  EXPECT_FALSE(FluxMapCsv(bad).ok());
  bad = m;
  std::swap(bad.id_a[0], bad.id_a[1]);
  EXPECT_FALSE(FluxMapCsv(bad).ok());
  bad = m;
  bad.psi_d_wb.pop_back();
  EXPECT_FALSE(WriteFluxMapCsv((dir / "x.csv").string(), bad).ok());
}

// Mutations of a valid map (bit flips, random bytes, deletions, duplicated
// ranges, tokens that broke readers): the parser always returns, an
// accepted map is a full grid of finite values, and a rejection names the
// file and a line and is printable.
TEST(FluxMap, MutatedMapsNeverCrashAndAlwaysNameFileAndLine) {
  const std::string base = SmallMap("id_A,iq_A,psi_d_Vs,psi_q_Vs,psi_d_sym_Vs,psi_q_sym_Vs,extra");
  // Widen the rows to the header (sym pair and extra column).
  std::string valid;
  {
    std::istringstream in(base);
    std::string line;
    std::getline(in, line);
    valid = line + "\n";
    while (std::getline(in, line)) valid += line + ",0.1,0,z\n";
  }
  ASSERT_TRUE(ParseFluxMapCsv(valid, "m.csv").ok());
  const std::vector<std::string> tokens = {"1e999", "nan", "inf", "-0", ",", ",,", "\n", "\r\n", "\"", "\xff",
                                           std::string(1, '\0'), "#", "Id", "Fq", "4.9e-324", "+", "  "};
  std::mt19937_64 rng(11);
  size_t accepted = 0, rejected = 0;
  for (int run = 0; run < 20000; ++run) {
    std::string m = valid;
    for (int k = 0, n = 1 + static_cast<int>(rng() % 3); k < n; ++k) {
      const size_t pos = rng() % (m.size() + 1);
      switch (rng() % 5) {
        case 0: if (!m.empty()) m[pos % m.size()] ^= static_cast<char>(1u << (rng() % 8)); break;
        case 1: m.insert(pos, 1, static_cast<char>(rng() & 0xff)); break;
        case 2: if (!m.empty()) m.erase(pos % m.size(), 1 + rng() % 24); break;
        case 3: if (!m.empty()) { const size_t a = pos % m.size(); m.insert(a, m.substr(a, 1 + rng() % 40)); } break;
        default: m.insert(pos, tokens[rng() % tokens.size()]); break;
      }
    }
    for (auto columns : {FluxMapColumns::kRaw, FluxMapColumns::kSymmetrised}) {
      FluxMapReadOptions o;
      o.columns = columns;
      auto r = ParseFluxMapCsv(m, "m.csv", o);
      if (r.ok()) {
        ++accepted;
        ASSERT_TRUE(ValidateFluxMap(*r).ok()) << ValidateFluxMap(*r) << "\n" << m;
        continue;
      }
      ++rejected;
      const std::string msg(r.status().message());
      ASSERT_EQ(msg.rfind("m.csv:", 0), 0u) << msg;
      ASSERT_TRUE(msg.size() > 6 && msg[6] >= '1' && msg[6] <= '9') << msg;
      ASSERT_EQ(msg, Printable(msg)) << "not printable: " << msg;
    }
  }
  EXPECT_GT(accepted, 1000u);
  EXPECT_GT(rejected, 10000u);
}


// ---- Conventions of the field's tools and plausibility ---------------------

// The published map's nodes: id, iq, psi_d, psi_q (raw columns), as read.
struct Row {
  double id_a, iq_a, psi_d_wb, psi_q_wb;
};
std::vector<Row> BaldorRows() {
  auto m = ReadFluxMapCsv(kBaldor);
  EXPECT_TRUE(m.ok()) << m.status();
  std::vector<Row> rows;
  if (m.ok()) {
    for (const auto& p : m->Points()) rows.push_back({p.id_a, p.iq_a, p.psi_d_wb, p.psi_q_wb});
  }
  return rows;
}

// A CSV of `rows` under `header`, each row through `f` (17 digits).
std::string Csv(const std::string& header, const std::vector<Row>& rows,
                const std::function<std::array<double, 4>(const Row&)>& f) {
  std::string out = header + "\n";
  char buf[160];
  for (const auto& r : rows) {
    const auto v = f(r);
    std::snprintf(buf, sizeof buf, "%.17g,%.17g,%.17g,%.17g\n", v[0], v[1], v[2], v[3]);
    out += buf;
  }
  return out;
}

// Expects `got` to be the published map in fluxcal's convention, node by
// node within `rel` of the largest value (0: bit for bit).
void ExpectBaldor(const FluxMap& got, double rel) {
  auto want = ReadFluxMapCsv(kBaldor);
  ASSERT_TRUE(want.ok());
  ASSERT_EQ(got.id_a.size(), want->id_a.size());
  ASSERT_EQ(got.iq_a.size(), want->iq_a.size());
  for (size_t i = 0; i < got.id_a.size(); ++i) {
    EXPECT_NEAR(got.id_a[i], want->id_a[i], rel * 20) << "id axis [" << i << "], A";
    for (size_t j = 0; j < got.iq_a.size(); ++j) {
      if (i == 0) {
        EXPECT_NEAR(got.iq_a[j], want->iq_a[j], rel * 26) << "iq axis [" << j << "], A";
      }
      ASSERT_NEAR(got.psi_d_wb[i][j], want->psi_d_wb[i][j], rel * 1.4)
          << "psi_d at id " << want->id_a[i] << " A, iq " << want->iq_a[j] << " A, Wb";
      ASSERT_NEAR(got.psi_q_wb[i][j], want->psi_q_wb[i][j], rel * 1.4)
          << "psi_q at id " << want->id_a[i] << " A, iq " << want->iq_a[j] << " A, Wb";
    }
  }
}

// SyR-e's axes: d the high-permeance axis, the magnet on -q. The same
// machine in SyR-e's frame (Id = iq, Iq = -id, Fd = psi_q, Fq = -psi_d) is
// detected from its zero-current node and converted back exactly.
std::string BaldorInSyreAxes() {
  return Csv("Id,Iq,Fd,Fq", BaldorRows(),
             [](const Row& r) { return std::array<double, 4>{r.iq_a, -r.id_a, r.psi_q_wb, -r.psi_d_wb}; });
}

TEST(FluxMapConvention, SyreAxesAreDetectedAndConvertedExactly) {
  const std::string syre = BaldorInSyreAxes();
  auto m = ParseFluxMapCsv(syre, "syre.csv");
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->convention.axes, FluxMapAxes::kSyre);
  EXPECT_TRUE(m->convention.axes_detected);
  EXPECT_NE(m->convention.Describe().find("id = -Iq, iq = Id, psi_d = -Fq, psi_q = Fd"), std::string::npos)
      << m->convention.Describe();
  ExpectBaldor(*m, 0.0);   // negation is exact: bit for bit
  EXPECT_FALSE(std::signbit(m->id_a[10])) << "id = 0 must read as +0";

  FluxMapReadOptions o;
  o.convention.axes = FluxMapAxes::kSyre;
  auto given = ParseFluxMapCsv(syre, "syre.csv", o);
  ASSERT_TRUE(given.ok()) << given.status();
  EXPECT_FALSE(given->convention.axes_detected);
  ExpectBaldor(*given, 0.0);

  // Read as fluxcal's axes, the map is refused with the cause named; so is
  // a fluxcal map read as SyR-e's.
  for (auto axes : {FluxMapAxes::kFluxcal, FluxMapAxes::kMotulator}) {
    o.convention.axes = axes;
    ExpectError(syre, "m.csv:285: field 'Fq': the magnet lies on the -q axis", o);
    ExpectError(syre, "a SyR-e map (d the high-permeance axis, the magnet on -q)? give --convention syre", o);
  }
  o.convention.axes = FluxMapAxes::kSyre;
  auto native = ReadFileToString(kBaldor);
  ASSERT_TRUE(native.ok());
  ExpectError(*native, "m.csv:285: field 'psi_d_Vs': --convention syre: SyR-e's axes put the magnet on -q, but this "
                       "map has it on +d", o);
  // motulator's axes are fluxcal's: the published map reads as it is.
  o.convention.axes = FluxMapAxes::kMotulator;
  auto mot = ParseFluxMapCsv(*native, "m.csv", o);
  ASSERT_TRUE(mot.ok()) << mot.status();
  ExpectBaldor(*mot, 0.0);
}

TEST(FluxMapConvention, SwappedFluxColumnsAreRefusedAsSuch) {
  // The published map with its psi_d and psi_q headers exchanged.
  const std::string swapped =
      Csv("id_A,iq_A,psi_q_Vs,psi_d_Vs", BaldorRows(),
          [](const Row& r) { return std::array<double, 4>{r.id_a, r.iq_a, r.psi_d_wb, r.psi_q_wb}; });
  for (auto axes : {FluxMapAxes::kAuto, FluxMapAxes::kFluxcal, FluxMapAxes::kSyre}) {
    FluxMapReadOptions o;
    o.convention.axes = axes;
    ExpectError(swapped, "m.csv:285: field 'psi_q_Vs': the psi_d and psi_q columns look exchanged: the magnet flux "
                         "lies on +q", o);
    ExpectError(swapped, "and 'psi_d_Vs' is odd in iq while 'psi_q_Vs' is even over 273 mirrored node pairs", o);
  }
  // A machine without a magnet (no zero-current flux to tell) whose columns
  // are exchanged: the mirror symmetry names it.
  std::string synrm = "id_A,iq_A,psi_q_Vs,psi_d_Vs\n";
  for (int id = -10; id <= 10; id += 2) {
    for (int iq = -10; iq <= 10; iq += 2) {
      const double pd = 0.02 * id / (1 + 0.01 * std::abs(iq)), pq = 0.006 * iq * (1 - 0.002 * id * id);
      synrm += absl::StrFormat("%d,%d,%.17g,%.17g\n", id, iq, pd, pq);
    }
  }
  FluxMapReadOptions o;
  o.convention.axes = FluxMapAxes::kFluxcal;
  ExpectError(synrm, "m.csv:1: field 'psi_d_Vs': the psi_d and psi_q columns look exchanged: psi_d is odd in iq and "
                     "psi_q even over 55 mirrored node pairs", o);
  // With its columns named right it reads (given axes: no magnet to detect).
  std::string right = synrm;
  right.replace(0, right.find('\n'), "id_A,iq_A,psi_d_Vs,psi_q_Vs");
  auto m = ParseFluxMapCsv(right, "m.csv", o);
  ASSERT_TRUE(m.ok()) << m.status();
  ExpectError(right, "m.csv:62: field 'psi_d_Vs': no magnet flux at zero current (psi_d_Vs = 0 Wb, psi_q_Vs = 0 Wb "
                     "at id = iq = 0; under 2 % of the map's largest |psi|");
  ExpectError(right, "give --convention fluxcal|motulator|syre");
}

TEST(FluxMapConvention, FluxInMilliweberIsRefusedWithTheHintAndReadWithUnits) {
  const std::string mwb =
      Csv("id_A,iq_A,psi_d_Vs,psi_q_Vs", BaldorRows(),
          [](const Row& r) { return std::array<double, 4>{r.id_a, r.iq_a, 1e3 * r.psi_d_wb, 1e3 * r.psi_q_wb}; });
  ExpectError(mwb, "m.csv:285: field 'psi_d_Vs': psi_pm 444.1 Wb (the flux at zero current, read in Vs) is above the "
                   "10 Wb of a plausible machine: is the flux in mWb? give --units mWb");
  for (auto unit : {FluxUnit::kMWb, FluxUnit::kMVs}) {
    FluxMapReadOptions o;
    o.convention.flux_unit = unit;
    auto m = ParseFluxMapCsv(mwb, "m.csv", o);
    ASSERT_TRUE(m.ok()) << m.status();
    EXPECT_EQ(m->convention.flux_unit_source, "flag");
    EXPECT_NE(m->convention.detail.find("overrides the header's 'psi_d_Vs'"), std::string::npos)
        << m->convention.detail;
    // psi_pm = the flux at zero current: 0.44414573760687304 Wb in the file.
    EXPECT_NEAR(m->psi_d_wb[10][13], 0.44414573760687304, 1e-15) << "psi_pm, Wb";
    ExpectBaldor(*m, 1e-15);
  }
  // A header that says mWb is read as mWb without a flag.
  std::string said = mwb;
  said.replace(0, said.find('\n'), "id_A,iq_A,psi_d_mWb,psi_q_mWb");
  auto m = ParseFluxMapCsv(said, "m.csv");
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_EQ(m->convention.flux_unit, FluxUnit::kMWb);
  EXPECT_EQ(m->convention.flux_unit_source, "header");
  ExpectBaldor(*m, 1e-15);
  said.replace(0, said.find('\n'), "id_A,iq_A,psi_d_mWb,psi_q_Vs");
  ExpectError(said, "m.csv:1: field 'psi_q_Vs': its unit differs from the psi_d column's ('psi_d_mWb')");
  // Without a node at zero current, the largest |psi| says it.
  std::string no_zero = "id_A,iq_A,psi_d_Vs,psi_q_Vs\n";
  for (const auto& r : BaldorRows()) {
    if (r.id_a < 0) {
      absl::StrAppendFormat(&no_zero, "%.17g,%.17g,%.17g,%.17g\n", r.id_a, r.iq_a, 1e3 * r.psi_d_wb, 1e3 * r.psi_q_wb);
    }
  }
  ExpectError(no_zero, "m.csv:271: field 'psi_q_Vs': |psi| 1357 Wb at id = -2 A, iq = 26 A (read in Vs) is above the "
                       "10 Wb of a plausible machine: is the flux in mWb? give --units mWb");
}

TEST(FluxMapConvention, RmsAndPowerInvariantScalingConvertToPeak) {
  const auto rows = BaldorRows();
  // rms-valued dq currents: |i| = I_peak / sqrt(2).
  const std::string rms = Csv("id_A,iq_A,psi_d_Vs,psi_q_Vs", rows, [](const Row& r) {
    return std::array<double, 4>{r.id_a / std::sqrt(2.0), r.iq_a / std::sqrt(2.0), r.psi_d_wb, r.psi_q_wb};
  });
  FluxMapReadOptions o;
  o.convention.current = AmplitudeScaling::kRms;
  auto m = ParseFluxMapCsv(rms, "m.csv", o);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_DOUBLE_EQ(m->convention.current_factor, std::sqrt(2.0));
  ExpectBaldor(*m, 1e-15);
  // Read as peak, the same file is another machine: its currents 29 % low.
  auto as_peak = ParseFluxMapCsv(rms, "m.csv");
  ASSERT_TRUE(as_peak.ok());
  EXPECT_NEAR(as_peak->id_a.front(), -20.0 / std::sqrt(2.0), 1e-12);

  // Power-invariant Clarke: every dq quantity sqrt(3/2) x the peak value.
  const double k = std::sqrt(1.5);
  const std::string pinv = Csv("id_A,iq_A,psi_d_Vs,psi_q_Vs", rows, [k](const Row& r) {
    return std::array<double, 4>{k * r.id_a, k * r.iq_a, k * r.psi_d_wb, k * r.psi_q_wb};
  });
  o.convention.current = AmplitudeScaling::kPowerInvariant;
  o.convention.flux = AmplitudeScaling::kPowerInvariant;
  auto p = ParseFluxMapCsv(pinv, "m.csv", o);
  ASSERT_TRUE(p.ok()) << p.status();
  EXPECT_DOUBLE_EQ(p->convention.flux_factor, std::sqrt(2.0 / 3.0));
  ExpectBaldor(*p, 1e-15);
}

TEST(FluxMapConvention, AxesThatCannotBeToldNeedTheFlagAndWrongOnesAreNamed) {
  const auto rows = BaldorRows();
  // No node at zero current.
  std::string no_zero = "id_A,iq_A,Fd,Fq\n";
  for (const auto& r : rows) {
    if (r.id_a < 0) {
      absl::StrAppendFormat(&no_zero, "%.17g,%.17g,%.17g,%.17g\n", r.id_a, r.iq_a, r.psi_d_wb, r.psi_q_wb);
    }
  }
  ExpectError(no_zero, "m.csv:1: field 'Fd': no node at id = iq = 0: the magnet axis cannot be detected from the map; "
                       "give --convention fluxcal|motulator|syre (the header's 'Fd', 'Fq' are SyR-e's names");
  FluxMapReadOptions o;
  o.convention.axes = FluxMapAxes::kFluxcal;
  auto m = ParseFluxMapCsv(no_zero, "m.csv", o);
  ASSERT_TRUE(m.ok()) << m.status();
  EXPECT_NE(m->convention.detail.find("no node at zero current"), std::string::npos);

  // SyR-e's names on a map whose magnet says fluxcal's axes: the physics
  // decides, the note says so.
  auto named = ParseFluxMapCsv(Csv("Id,Iq,Fd,Fq", rows,
                                   [](const Row& r) {
                                     return std::array<double, 4>{r.id_a, r.iq_a, r.psi_d_wb, r.psi_q_wb};
                                   }),
                               "m.csv");
  ASSERT_TRUE(named.ok()) << named.status();
  EXPECT_EQ(named->convention.axes, FluxMapAxes::kFluxcal);
  EXPECT_NE(named->convention.detail.find("SyR-e's names"), std::string::npos) << named->convention.detail;

  // The magnet on -d: d reversed (id and psi_d negated).
  ExpectError(Csv("id_A,iq_A,psi_d_Vs,psi_q_Vs", rows,
                  [](const Row& r) { return std::array<double, 4>{-r.id_a, r.iq_a, -r.psi_d_wb, r.psi_q_wb}; }),
              "m.csv:285: field 'psi_d_Vs': the magnet lies on the -d axis");
  // The frame rotated by 30 degrees (an angle offset).
  const double c = std::cos(kPi30), s = std::sin(kPi30);
  ExpectError(Csv("id_A,iq_A,psi_d_Vs,psi_q_Vs", rows,
                  [&](const Row& r) {
                    return std::array<double, 4>{r.id_a, r.iq_a, c * r.psi_d_wb - s * r.psi_q_wb,
                                                 s * r.psi_d_wb + c * r.psi_q_wb};
                  }),
              "points at 30.0 deg, not along an axis (within 10 deg)");
}

TEST(FluxMapConvention, ImplausibleValuesNameTheLikelyCause) {
  const auto rows = BaldorRows();
  auto with = [&](double ki, double kd_sign) {
    return Csv("id_A,iq_A,psi_d_Vs,psi_q_Vs", rows, [=](const Row& r) {
      return std::array<double, 4>{kd_sign * ki * r.id_a, ki * r.iq_a, r.psi_d_wb, r.psi_q_wb};
    });
  };
  // Currents in mA: beyond the service's 10 kA.
  ExpectError(with(1e3, 1), "m.csv:2: field 'id_A': current -20000 A (read as peak) is beyond the +-10 kA of a "
                            "plausible machine: are the currents in mA?");
  // Currents in kA: the map's own inductances 1000 x too large.
  ExpectError(with(1e-3, 1), "m.csv:1: field 'psi_d_Vs': differential inductance L_dd = dpsi_d/did");
  ExpectError(with(1e-3, 1), "is outside the plausible [1e-07, 1) H: is the flux in mWb (give --units mWb) or the "
                             "current in kA?");
  // id negated alone: psi_d falls as id rises.
  ExpectError(with(1, -1), "psi_d falls as id rises: is psi_d or id negated (the d axis reversed)?");
  // A column copied: psi_q constant in iq (and so even: the symmetry
  // check names it first where the map has mirrored nodes).
  std::string flat = "id_A,iq_A,psi_d_Vs,psi_q_Vs\n";
  for (const auto& r : rows) {
    if (r.iq_a >= 0) absl::StrAppendFormat(&flat, "%.17g,%.17g,%.17g,0.01\n", r.id_a, r.iq_a, r.psi_d_wb);
  }
  ExpectError(flat, "L_qq = dpsi_q/diq 0 H (median of the map's 273 differences) is outside the plausible [1e-07, 1) "
                    "H: the flux barely changes with the current");
}

}  // namespace
}  // namespace fluxcal::io
