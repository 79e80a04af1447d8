// Tests of the flux-map reader/writer: the published map of a real machine
// reads as its 21 x 27 grid, the spellings the field's tools use are
// accepted, every malformed input yields an error naming file, line and
// field, and a written map reads back bit for bit.
#include "io/flux_map.h"

#include <cmath>
#include <filesystem>
#include <random>
#include <sstream>

#include "gtest/gtest.h"
#include "io/csv.h"

namespace fluxcal::io {
namespace {

namespace fs = std::filesystem;

const std::string kBaldor = std::string(FLUXCAL_SHARED_DIR) + "/examples/real/baldor_fluxmap_measured.csv";

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
  ExpectError("id_A,iq_A,psi_d_Vs\n-2,0,0.09\n", "m.csv:1: field 'psi_q': missing column (accepted, any case: psi_q_Vs, psi_q_Wb, psi_q, psiq, Fq; header has id_A, iq_A, psi_d_Vs)");
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
  // Values no short decimal represents, of every magnitude a map holds.
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  FluxMap m;
  for (int i = 0; i < 13; ++i) m.id_a.push_back(-150.0 + 12.5 * i + (i == 3 ? 1e-13 : 0.0) + u(rng) * 1e-3);
  for (int j = 0; j < 9; ++j) m.iq_a.push_back(std::ldexp(static_cast<double>(j), -3) * 17.0 / 3.0);
  m.psi_d_wb.assign(13, std::vector<double>(9));
  m.psi_q_wb = m.psi_d_wb;
  for (int i = 0; i < 13; ++i) {
    for (int j = 0; j < 9; ++j) {
      m.psi_d_wb[i][j] = 0.01 + u(rng) / 3.0;
      m.psi_q_wb[i][j] = u(rng) * std::pow(10.0, -(i + j) % 7) / 7.0;
    }
  }
  m.psi_q_wb[0][0] = 5e-324;   // subnormal
  auto text = FluxMapCsv(m);
  ASSERT_TRUE(text.ok()) << text.status();
  EXPECT_EQ(text->rfind("id_A,iq_A,psi_d_Vs,psi_q_Vs\n", 0), 0u);
  auto back = ParseFluxMapCsv(*text, "m.csv");
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

}  // namespace
}  // namespace fluxcal::io
