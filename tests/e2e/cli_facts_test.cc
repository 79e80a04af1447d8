// No invented machine facts, end to end through `fluxcal` (issue 24):
//  - a bare hf_results.csv is refused until --serial, --pole-pairs and
//    --psi-pm-wb are given (before: serial UNKNOWN, 4 pole pairs, psi_pm 0
//    and a torque standard deviation of thousands of N m);
//  - flags that contradict a set's manifest are refused;
//  - fw and mtpv exports take Udc from the calibration or --udc-v and
//    refuse without (before: 50 V, silently); MTPA needs none;
//  - a mostly clamped table is refused unless --allow-clamped, and any
//    clamped cell is warned about;
//  - breakpoints are round, the torque axis holds 0;
//  - a report without the facts its verdict needs never says pass, and
//    without Udc it says that the voltage limit cannot be drawn.
// In-repo data: the twin's set, identified here and written out as a bare
// hf_results.csv. The published Baldor EOL file (data/real/baldor_eol)
// repeats the original report.
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "tests/e2e/fluxcal_run.h"

namespace fluxcal::e2e {
namespace {

namespace fs = std::filesystem;

nlohmann::json JsonOf(const RunResult& r) {
  EXPECT_EQ(r.code, 0) << r.err;
  return nlohmann::json::parse(r.out);
}


// The first column of a table CSV (comment lines skipped), distinct values
// in order.
std::vector<double> FirstColumn(const std::string& path, size_t column = 0) {
  std::ifstream in(path);
  std::string line;
  std::vector<double> v;
  bool header = true;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    if (header) { header = false; continue; }
    std::stringstream ss(line);
    std::string cell;
    for (size_t k = 0; k <= column; ++k) std::getline(ss, cell, ',');
    const double x = std::stod(cell);
    if (std::find(v.begin(), v.end(), x) == v.end()) v.push_back(x);
  }
  return v;
}

// An axis of round breakpoints: equally spaced by 1, 2 or 5 x 10^k, each
// value the double nearest its decimal.
void ExpectRoundAxis(const std::vector<double>& v, const std::string& what) {
  ASSERT_GE(v.size(), 2u) << what;
  const double step = v[1] - v[0];
  const double mag = std::pow(10.0, std::floor(std::log10(step) + 1e-9));
  const double mant = step / mag;
  EXPECT_TRUE(std::abs(mant - 1) < 1e-9 || std::abs(mant - 2) < 1e-9 || std::abs(mant - 5) < 1e-9)
      << what << ": step " << step << " is not 1, 2 or 5 x 10^k";
  for (size_t k = 0; k < v.size(); ++k) {
    const double n = v[k] / step;
    EXPECT_NEAR(n, std::round(n), 1e-9) << what << ": " << v[k] << " is not a multiple of " << step;
    // %.17g of a breakpoint is its short decimal (k m / 10^e rounded once).
    std::ostringstream s;
    s.precision(15);
    s << v[k];
    EXPECT_EQ(std::stod(s.str()), v[k]) << what << ": " << v[k] << " is not the double nearest a round decimal";
  }
}

class Facts : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fluxcal::e2e::FreshTempDir("fluxcal_facts_"));
    const std::string set = Path("set");
    ASSERT_EQ(RunFluxcal("simulate --out " + set + " --seed 7 --serial IPM-FACTS-1").code, 0);
    // The bench's own identification as a bare hf_results.csv: no manifest,
    // nothing about the machine.
    const auto id = JsonOf(RunFluxcal("identify " + set + " --json"));
    std::ofstream hf(Path("hf_results.csv"));
    hf << "id_a,iq_a,speed_rpm,ld_h,lq_h,ldq_h,temperature_c\n";
    hf.precision(17);
    for (const auto& p : id["points"]) {
      hf << p["id_a"].get<double>() << "," << p["iq_a"].get<double>() << ",0," << p["ld_h"].get<double>() << ","
         << p["lq_h"].get<double>() << "," << p["ldq_h"].get<double>() << ",25\n";
    }
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    fs::remove(Path("set") + ".truth.json");
    delete dir_;
  }
  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }
  // The calibration of the bare file with the facts given (the twin's:
  // 4 pole pairs, psi_pm 11.4 mWb, Rs 11 mOhm); no Udc.
  static std::string FactsCalibration() {
    const std::string cal = Path("hf_cal.json");
    if (!fs::exists(cal)) {
      EXPECT_EQ(RunFluxcal("fit " + Path("hf_results.csv") + " --serial IPM-FACTS-1 --pole-pairs 4 --psi-pm-wb 0.0114 "
                           "--rs-ohm 0.011 --model analytic --out " + cal).code, 0);
    }
    return cal;
  }
  static fs::path* dir_;
};
fs::path* Facts::dir_ = nullptr;

TEST_F(Facts, BareHfResultsNeedsTheFacts) {
  const std::string hf = Path("hf_results.csv"), out = Path("refused.json");
  const RunResult none = RunFluxcal("fit " + hf + " --out " + out);
  EXPECT_EQ(none.code, 2) << none.err;
  for (const char* flag : {"--serial", "--pole-pairs", "--psi-pm-wb"}) EXPECT_TRUE(Has(none.err, flag)) << none.err;
  EXPECT_TRUE(Has(none.err, "not observable from differential inductances alone")) << none.err;
  EXPECT_FALSE(fs::exists(out)) << "nothing written on a refusal";
  // Only what is still missing is named.
  const RunResult some = RunFluxcal("fit " + hf + " --serial IPM-FACTS-1 --pole-pairs 4 --out " + out);
  EXPECT_EQ(some.code, 2);
  EXPECT_TRUE(Has(some.err, "--psi-pm-wb")) << some.err;
  EXPECT_FALSE(Has(some.err, "--serial S")) << some.err;
  EXPECT_FALSE(Has(some.err, "--pole-pairs P")) << some.err;
  EXPECT_EQ(RunFluxcal("fit " + hf + " --serial IPM-FACTS-1 --pole-pairs 0 --psi-pm-wb 0.0114 --out " + out).code, 2);

  // With the facts: they are in the calibration as given; Udc, not given,
  // is absent (not 50 V).
  const auto cal = JsonOf(RunFluxcal("fit " + hf + " --serial IPM-FACTS-1 --pole-pairs 4 --psi-pm-wb 0.0114 "
                                     "--rs-ohm 0.011 --model analytic --out " + out + " --json"));
  EXPECT_EQ(cal["serial"], "IPM-FACTS-1");
  EXPECT_EQ(cal["pole_pairs"], 4);
  EXPECT_EQ(cal["psi_pm_nominal_wb"].get<double>(), 0.0114);
  EXPECT_EQ(cal["rs_ohm"].get<double>(), 0.011);
  EXPECT_FALSE(cal.contains("udc_v"));
  EXPECT_NEAR(cal["psi_pm_wb"].get<double>(), 0.0114, 0.0114 * 0.05);
  // The torque it predicts has a standard deviation of the prior's order
  // (5 % of psi_pm), not thousands of N m.
  const auto q = JsonOf(RunFluxcal("query " + out + " --id-a -20 --iq-a 40 --json"));
  const double t = q["torque_nm"].get<double>(), t_std = q["torque_nm_std"].get<double>();
  EXPECT_GT(t, 0.0);
  EXPECT_LT(t_std, 0.1 * t) << "torque " << t << " N m +- " << t_std << " N m";
}

TEST_F(Facts, FlagsContradictingTheSetAreRefused) {
  const std::string set = Path("set"), out = Path("conflict.json");
  const RunResult pp = RunFluxcal("fit " + set + " --pole-pairs 3 --out " + out);
  EXPECT_EQ(pp.code, 2);
  EXPECT_TRUE(Has(pp.err, "flag --pole-pairs: 3 differs from the set's manifest's pole_pairs 4")) << pp.err;
  const RunResult serial = RunFluxcal("fit " + set + " --serial OTHER-1 --out " + out);
  EXPECT_EQ(serial.code, 2);
  EXPECT_TRUE(Has(serial.err, "--serial")) << serial.err;
  const RunResult udc = RunFluxcal("fit " + set + " --udc-v 48 --out " + out);
  EXPECT_EQ(udc.code, 2);
  EXPECT_TRUE(Has(udc.err, "udc_v 50")) << udc.err;
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(Facts, ExportsTakeUdcFromTheCalibrationOrTheFlag) {
  const std::string cal = FactsCalibration();
  for (const char* table : {"fw", "mtpv"}) {
    const RunResult r = RunFluxcal("export " + cal + " --table " + table + " --out " + Path("x.csv"));
    EXPECT_EQ(r.code, 2) << table;
    EXPECT_TRUE(Has(r.err, "flag --udc-v")) << table << ": " << r.err;
    EXPECT_FALSE(fs::exists(Path("x.csv"))) << table;
  }
  // MTPA needs no Udc: none is stated in the file.
  const std::string mtpa = Path("mtpa.csv");
  const auto a = JsonOf(RunFluxcal("export " + cal + " --table mtpa --out " + mtpa + " --json"));
  EXPECT_TRUE(a["udc_v"].is_null());
  EXPECT_TRUE(a["u_max_v"].is_null());
  std::ifstream in(mtpa);
  const std::string text((std::istreambuf_iterator<char>(in)), {});
  EXPECT_FALSE(Has(text, "# udc_v:")) << "no Udc written that the table was not computed for";
  // Round torque rows, 0 among them, both quadrants, at most --points.
  const auto tq = FirstColumn(mtpa);
  ExpectRoundAxis(tq, "mtpa torque_nm");
  EXPECT_NE(std::find(tq.begin(), tq.end(), 0.0), tq.end()) << "the torque axis holds 0";
  EXPECT_LT(tq.front(), 0.0);
  EXPECT_LE(tq.size(), 64u);
  EXPECT_EQ(a["clamped_cells"], 0);

  // fw with --udc-v: the flag's value, said where it came from; round axes.
  const std::string fw = Path("fw.csv");
  const auto f = JsonOf(RunFluxcal("export " + cal + " --table fw --udc-v 50 --out " + fw + " --json"));
  EXPECT_EQ(f["udc_v"].get<double>(), 50.0);
  EXPECT_EQ(f["sources"]["udc_v"], "--udc-v");
  ExpectRoundAxis(FirstColumn(fw, 0), "fw torque_nm");
  ExpectRoundAxis(FirstColumn(fw, 1), "fw speed_rpm");
  EXPECT_LE(f["clamped_share"].get<double>(), 0.5);
  EXPECT_DOUBLE_EQ(f["clamped_share"].get<double>(), f["clamped_cells"].get<double>() / f["cells"].get<double>());

  // A calibration of the set carries the set's Udc; fw takes it from there.
  const std::string set_cal = Path("set_cal.json");
  const auto c = JsonOf(RunFluxcal("fit " + Path("set") + " --model analytic --out " + set_cal + " --json"));
  EXPECT_EQ(c["udc_v"].get<double>(), 50.0) << "the manifest's drive.udc_v";
  const auto g = JsonOf(RunFluxcal("export " + set_cal + " --table fw --force --out " + fw + " --json"));
  EXPECT_EQ(g["udc_v"].get<double>(), 50.0);
  EXPECT_EQ(g["sources"]["udc_v"], "the calibration");
  ExpectRoundAxis(FirstColumn(Path("fw.csv"), 1), "fw speed_rpm");
  const auto v = JsonOf(RunFluxcal("export " + set_cal + " --table mtpv --out " + Path("mtpv.csv") + " --json"));
  ExpectRoundAxis(FirstColumn(Path("mtpv.csv")), "mtpv psi_wb");
}

TEST_F(Facts, MostlyClampedTableIsRefusedUnlessAskedFor) {
  const std::string cal = FactsCalibration(), fw = Path("clamped.csv");
  // 8 V leaves the twin almost no speed before the voltage limit.
  const RunResult r = RunFluxcal("export " + cal + " --table fw --udc-v 8 --out " + fw + " --json");
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_TRUE(r.out.empty()) << "no summary for a refused table";
  EXPECT_FALSE(fs::exists(fw));
  EXPECT_TRUE(Has(r.err, "cells (")) << r.err;
  EXPECT_TRUE(Has(r.err, "clamped, more than 50 %")) << r.err;
  EXPECT_TRUE(Has(r.err, "the voltage limit u_max")) << r.err;
  EXPECT_TRUE(Has(r.err, "Udc 8 V")) << r.err;
  EXPECT_TRUE(Has(r.err, "--allow-clamped")) << r.err;
  const RunResult ok = RunFluxcal("export " + cal + " --table fw --udc-v 8 --allow-clamped --out " + fw + " --json");
  const auto j = JsonOf(ok);
  EXPECT_GT(j["clamped_share"].get<double>(), 0.5);
  EXPECT_TRUE(Has(ok.err, "warning:")) << ok.err;
  EXPECT_TRUE(fs::exists(fw));
  // Any clamped cell is warned about, also below the threshold.
  const RunResult some = RunFluxcal("export " + cal + " --table fw --udc-v 50 --force --out " + fw + " --json");
  const auto s = JsonOf(some);
  ASSERT_GT(s["clamped_cells"].get<int>(), 0);
  EXPECT_TRUE(Has(some.err, "warning: " + std::to_string(s["clamped_cells"].get<int>()) + " of ")) << some.err;
}

TEST_F(Facts, ReportWithoutTheFactsNeverPasses) {
  const std::string cal = FactsCalibration();
  // The facts given, Udc not: the verdict can pass, the page says the
  // voltage limit cannot be drawn.
  const std::string page = Path("r.html");
  const auto r = JsonOf(RunFluxcal("report " + cal + " --out " + page + " --json"));
  EXPECT_EQ(r["verdict"], "pass");
  EXPECT_EQ(r["voltage_limit_speed_rpm"].get<double>(), 0.0);
  {
    std::ifstream in(page);
    const std::string html((std::istreambuf_iterator<char>(in)), {});
    EXPECT_TRUE(Has(html, "The voltage limit and the field-weakening map cannot be drawn"));
  }
  const auto with_udc = JsonOf(RunFluxcal("report " + cal + " --udc-v 50 --force --out " + page + " --json"));
  EXPECT_GT(with_udc["voltage_limit_speed_rpm"].get<double>(), 0.0);

  // A calibration file that does not state the nominal psi_pm (as every
  // file written before it did not): no pass.
  nlohmann::json j;
  std::ifstream(cal) >> j;
  j.erase("psi_pm_nominal_wb");
  j["rs_ohm"] = 0.0;   // how older files wrote an Rs nobody stated
  const std::string old = Path("old_cal.json");
  std::ofstream(old) << j.dump(2);
  const auto o = JsonOf(RunFluxcal("report " + old + " --force --out " + page + " --json"));
  EXPECT_EQ(o["verdict"].get<std::string>().rfind("fail: nominal psi_pm unknown", 0), 0u) << o["verdict"];
  std::ifstream in(page);
  const std::string html((std::istreambuf_iterator<char>(in)), {});
  EXPECT_TRUE(Has(html, "Rs (nominal) / pole pairs</th><td>not known / 4")) << "rs_ohm 0 of an old file read as unknown";
}

// The defect as first reported, on the published Baldor EOL file.
TEST(FactsBaldor, AsReported) {
  const std::string hf = std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_eol/hf_results.csv";
  ASSERT_TRUE(fs::exists(hf)) << "in-repo fixture missing: " << hf;
  const fs::path dir = fs::temp_directory_path() / ("fluxcal_facts_baldor_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const std::string cal = (dir / "c.json").string(), out = (dir / "fw.csv").string();
  EXPECT_EQ(RunFluxcal("fit " + hf + " --out " + cal).code, 2);
  ASSERT_EQ(RunFluxcal("fit " + hf + " --serial REAL-baldor-7 --pole-pairs 2 --psi-pm-wb 0.444 --rs-ohm 3.6 --out " +
                       cal).code, 0);
  const auto q = JsonOf(RunFluxcal("query " + cal + " --id-a -10 --iq-a 10 --json"));
  EXPECT_LT(q["torque_nm_std"].get<double>(), 0.1 * q["torque_nm"].get<double>());
  EXPECT_EQ(RunFluxcal("export " + cal + " --table fw --out " + out).code, 2);   // no Udc: asks for --udc-v
  const RunResult at50 = RunFluxcal("export " + cal + " --table fw --udc-v 50 --out " + out);
  EXPECT_EQ(at50.code, 1) << "50 V is far below this machine's 540 V: mostly clamped";
  const auto at540 = JsonOf(RunFluxcal("export " + cal + " --table fw --udc-v 540 --out " + out + " --json"));
  EXPECT_LT(at540["clamped_share"].get<double>(), 0.5);
  fs::remove_all(dir);
}

}  // namespace
}  // namespace fluxcal::e2e
