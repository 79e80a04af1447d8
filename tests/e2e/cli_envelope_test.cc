// The envelope and the Udc axis end to end through `fluxcal export`
// (docs/tables.md, "The envelope", "Tables over Udc", "Magnet
// temperature"), on the published Baldor EOL set (data/real/baldor_eol,
// 540 V DC link in its manifest):
//  - `--table envelope --udc-axis-v` writes one file per Udc and one
//    figure with a curve per Udc;
//  - each file's values are the single export's at that Udc, bit for bit
//    (the payload SHA-256 the files carry);
//  - torque never rises with speed and never falls with Udc;
//  - --magnet-temp-c is refused: the calibration states no coefficient;
//    with the coefficient and the flux map's temperature stated (a
//    simulated set's manifest, `fit --map` flags), the tables at the magnet
//    temperature state it, and what is missing is named.
#include <unistd.h>

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


// Column `name` of a table CSV (comment lines skipped).
std::vector<double> Column(const std::string& path, const std::string& name) {
  std::ifstream in(path);
  std::string line;
  std::vector<double> v;
  int col = -1;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    std::stringstream ss(line);
    std::string cell;
    std::vector<std::string> cells;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    if (col < 0) {
      for (size_t k = 0; k < cells.size(); ++k) {
        if (cells[k] == name) col = static_cast<int>(k);
      }
      if (col < 0) return {};
      continue;
    }
    v.push_back(std::stod(cells[static_cast<size_t>(col)]));
  }
  return v;
}

// The published Baldor EOL set (in the repository) fitted into cal.
::testing::AssertionResult FitBaldorEol(const std::string& cal) {
  const std::string set = std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_eol";
  if (!fs::exists(set + "/manifest.json")) return ::testing::AssertionFailure() << "in-repo fixture missing: " << set;
  const RunResult fit = RunFluxcal("fit " + set + " --out " + cal);
  if (fit.code != 0) return ::testing::AssertionFailure() << "fit exited " << fit.code << ": " << fit.err;
  return ::testing::AssertionSuccess();
}

TEST(EnvelopeCli, UdcAxisFilesEqualSingleExportsAndTheFigureHasACurvePerUdc) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_envelope_");
  auto path = [&](const std::string& name) { return (dir / name).string(); };
  const std::string cal = path("c.json");
  ASSERT_TRUE(FitBaldorEol(cal));

  const std::vector<int> udcs = {300, 400, 540};
  const RunResult axis = RunFluxcal("export " + cal + " --table envelope --udc-axis-v 300,400,540 --out " +
                                    path("env.csv") + " --svg " + path("env.svg") + " --json");
  ASSERT_EQ(axis.code, 0) << axis.err;
  const auto j = nlohmann::json::parse(axis.out);
  ASSERT_EQ(j["files"].size(), udcs.size());
  std::vector<std::vector<double>> torque;
  for (size_t k = 0; k < udcs.size(); ++k) {
    const std::string file = path("env_udc" + std::to_string(udcs[k]) + "v.csv");
    EXPECT_EQ(j["files"][k]["out"], file);
    ASSERT_TRUE(fs::exists(file));
    // The single export at this Udc: the same values.
    const RunResult one = RunFluxcal("export " + cal + " --table envelope --udc-v " + std::to_string(udcs[k]) +
                                     " --out " + path("one_" + std::to_string(udcs[k]) + ".csv") + " --json");
    ASSERT_EQ(one.code, 0) << one.err;
    const auto o = nlohmann::json::parse(one.out);
    EXPECT_EQ(j["files"][k]["payload_sha256"], o["payload_sha256"]) << udcs[k] << " V";
    EXPECT_EQ(Column(file, "torque_nm"), Column(path("one_" + std::to_string(udcs[k]) + ".csv"), "torque_nm"));
    torque.push_back(Column(file, "torque_nm"));
    const auto& t = torque.back();
    ASSERT_GT(t.size(), 10u);
    for (size_t i = 1; i < t.size(); ++i) {
      EXPECT_LE(t[i], t[i - 1] * (1 + 1e-6)) << udcs[k] << " V: torque rises at row " << i;
    }
    if (k > 0) {
      for (size_t i = 0; i < t.size(); ++i) {
        EXPECT_GE(t[i], torque[k - 1][i] * (1 - 1e-6)) << "row " << i << ": " << udcs[k] << " V below "
                                                       << udcs[k - 1] << " V";
      }
    }
  }
  // At 300 V the envelope is far below the 540 V one at the top speed.
  EXPECT_LT(torque[0].back(), 0.5 * torque[2].back());
  const std::string svg = ReadFile(path("env.svg"));
  for (int u : udcs) EXPECT_TRUE(Has(svg, "Udc " + std::to_string(u) + " V")) << u;

  // A field-weakening header per Udc, labels carrying the voltage.
  const RunResult fw = RunFluxcal("export " + cal + " --table fw --format h --udc-axis-v 400:540:2 --out " +
                                  path("fw.h") + " --json");
  ASSERT_EQ(fw.code, 0) << fw.err;
  const auto f = nlohmann::json::parse(fw.out);
  ASSERT_EQ(f["files"].size(), 2u);
  EXPECT_TRUE(Has(ReadFile(path("fw_udc540v.h")), "fluxcal_fw_udc540v_id_a["));
  const RunResult fw540 = RunFluxcal("export " + cal + " --table fw --format h --out " + path("fw540.h") + " --json");
  ASSERT_EQ(fw540.code, 0) << fw540.err;
  EXPECT_EQ(f["files"][1]["payload_sha256"], nlohmann::json::parse(fw540.out)["payload_sha256"]);

  // Refusals: a magnet temperature without the calibration's coefficient,
  // one Udc and an axis together, an axis to stdout.
  const RunResult hot = RunFluxcal("export " + cal + " --table envelope --magnet-temp-c 120 --out " + path("hot.csv"));
  EXPECT_EQ(hot.code, 2) << hot.err;
  EXPECT_TRUE(Has(hot.err, "flag --magnet-temp-c: the calibration of REAL-baldor-7 states no magnet temperature "
                           "coefficient")) << hot.err;
  EXPECT_FALSE(fs::exists(path("hot.csv")));
  EXPECT_EQ(RunFluxcal("export " + cal + " --udc-v 540 --udc-axis-v 300,400 --out " + path("x.csv")).code, 2);
  EXPECT_EQ(RunFluxcal("export " + cal + " --udc-axis-v 300,400 --out -").code, 2);
  fs::remove_all(dir);
}

// `fluxcal export --table envelope --generating` (docs/cli.md): the
// generating limit on the Baldor set, torque and power <= 0 at every
// speed, at standstill the motoring limit mirrored (the fitted model is
// symmetric in iq), at speed at least the motoring one; the A2L and C
// header under labels of their own (FLUXCAL_ENVELOPE_GENERATING_*), also
// over a Udc axis; the flag with another table a usage error naming it,
// nothing written.
TEST(EnvelopeCli, GeneratingEnvelopeUnderLabelsOfItsOwn) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_generating_");
  auto path = [&](const std::string& name) { return (dir / name).string(); };
  const std::string cal = path("c.json");
  ASSERT_TRUE(FitBaldorEol(cal));

  const RunResult mot = RunFluxcal("export " + cal + " --table envelope --out " + path("m.csv") + " --json");
  ASSERT_EQ(mot.code, 0) << mot.err;
  const RunResult gen = RunFluxcal("export " + cal + " --table envelope --generating --out " + path("g.csv") +
                                   " --svg " + path("g.svg") + " --json");
  ASSERT_EQ(gen.code, 0) << gen.err;
  const auto jm = nlohmann::json::parse(mot.out), jg = nlohmann::json::parse(gen.out);
  EXPECT_EQ(jm["generating"], false);
  EXPECT_EQ(jg["generating"], true);
  EXPECT_EQ(jg["label_tag"], "generating");
  EXPECT_EQ(jg["udc_v"], 540.0) << "the set's DC link";
  EXPECT_NE(jg["payload_sha256"], jm["payload_sha256"]);
  EXPECT_TRUE(Has(ReadFile(path("g.csv")), "# fluxcal envelope (generating) table\n"));
  const auto tm = Column(path("m.csv"), "torque_nm"), tg = Column(path("g.csv"), "torque_nm");
  const auto pg = Column(path("g.csv"), "power_w");
  ASSERT_EQ(tm.size(), tg.size());
  ASSERT_GT(tg.size(), 10u);
  for (size_t i = 0; i < tg.size(); ++i) {
    EXPECT_LE(tg[i], 0.0) << "row " << i;
    EXPECT_LE(pg[i], 0.0) << "row " << i;
    EXPECT_GE(-tg[i], tm[i] * (1 - 1e-6)) << "row " << i << ": generating limit below the motoring one";
  }
  EXPECT_NEAR(-tg[0], tm[0], 1e-9 * tm[0]);
  EXPECT_TRUE(Has(ReadFile(path("g.svg")), "<svg"));

  // A2L and C header: labels of their own, so that both directions flash side by side.
  ASSERT_EQ(RunFluxcal("export " + cal + " --table envelope --generating --format a2l --out " + path("g.a2l")).code, 0);
  ASSERT_EQ(RunFluxcal("export " + cal + " --table envelope --generating --format h --out " + path("g.h")).code, 0);
  const std::string a2l = ReadFile(path("g.a2l")), h = ReadFile(path("g.h"));
  EXPECT_TRUE(Has(a2l, "/begin CHARACTERISTIC FLUXCAL_ENVELOPE_GENERATING_TORQUE_NM")) << a2l.substr(0, 2000);
  EXPECT_FALSE(Has(a2l, "FLUXCAL_ENVELOPE_TORQUE_NM"));
  EXPECT_TRUE(Has(h, "#define FLUXCAL_ENVELOPE_GENERATING_TORQUE_SIGN -1\n"));
  EXPECT_TRUE(Has(h, "fluxcal_envelope_generating_torque_nm["));

  // Over a Udc axis: both tags in every label.
  const RunResult axis = RunFluxcal("export " + cal + " --table envelope --generating --format dcm --udc-axis-v 400,540 "
                                    "--out " + path("g.dcm") + " --json");
  ASSERT_EQ(axis.code, 0) << axis.err;
  EXPECT_EQ(nlohmann::json::parse(axis.out)["files"][1]["label_tag"], "generating_udc540v");
  EXPECT_TRUE(Has(ReadFile(path("g_udc540v.dcm")), "KENNLINIE FLUXCAL_ENVELOPE_GENERATING_UDC540V_TORQUE_NM "));

  // Only with the envelope: a usage error naming the flag, nothing written.
  for (const char* table : {"mtpa", "mtpv", "fw"}) {
    const RunResult bad = RunFluxcal("export " + cal + " --table " + table + " --generating --out " + path("bad.csv"));
    EXPECT_EQ(bad.code, 2) << table << ": " << bad.err;
    EXPECT_TRUE(Has(bad.err, "flag --generating: only with --table envelope")) << bad.err;
    EXPECT_FALSE(fs::exists(path("bad.csv")));
  }
  const RunResult no_table = RunFluxcal("export " + cal + " --generating --out " + path("bad.csv"));
  EXPECT_EQ(no_table.code, 2) << "the default table is mtpa: " << no_table.err;
  fs::remove_all(dir);
}

// The coefficient from the manifest (motor.psi_pm_temp_coeff_per_k), the
// reference from the temperatures the twin's set records (25 degC): the
// MTPA table at 100 degC states both and psi_pm x (1 - 0.0012 x 75). A bad
// coefficient is refused naming the manifest's line and field.
TEST(EnvelopeCli, MagnetTemperatureFromTheSetOrTheFlags) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_magnet_");
  auto path = [&](const std::string& name) { return (dir / name).string(); };
  ASSERT_EQ(RunFluxcal("simulate --serial IPM-MAGNET-E2E --out " + path("set")).code, 0);
  const std::string manifest = path("set/manifest.json");
  nlohmann::json m = nlohmann::json::parse(ReadFile(manifest));
  m["motor"]["psi_pm_temp_coeff_per_k"] = -0.0012;
  std::ofstream(manifest) << m.dump(2);
  const RunResult fit = RunFluxcal("fit " + path("set") + " --out " + path("c.json"));
  ASSERT_EQ(fit.code, 0) << fit.err;
  EXPECT_TRUE(Has(fit.err, "fit: magnet temperature: psi_pm changes by -0.12 %/K of magnet temperature (stated); "
                           "flux map at 25 degC")) << fit.err;
  const RunResult hot = RunFluxcal("export " + path("c.json") + " --table mtpa --magnet-temp-c 100 --out " +
                                   path("hot.csv"));
  ASSERT_EQ(hot.code, 0) << hot.err;
  EXPECT_TRUE(Has(hot.err, "export: note: magnets at 100 degC: psi_pm x 0.91 ")) << hot.err;
  const std::string csv = ReadFile(path("hot.csv"));
  for (const char* line : {"# magnet_temperature_c: 100 degC", "# magnet_reference_c: 25 degC",
                           "# magnet_reference_spread_k: 0 K", "# magnet_alpha_per_k: -0.00119999999",
                           "# psi_pm_scale: 0.9100000000"}) {
    EXPECT_TRUE(Has(csv, line)) << line << " not in\n" << csv.substr(0, 2000);
  }
  // A coefficient in %/K.
  m["motor"]["psi_pm_temp_coeff_per_k"] = -0.12;
  std::ofstream(manifest) << m.dump(2);
  const RunResult bad = RunFluxcal("fit " + path("set") + " --out " + path("bad.json"));
  EXPECT_NE(bad.code, 0);
  EXPECT_TRUE(Has(bad.err, manifest + ":") && Has(bad.err, "field 'motor.psi_pm_temp_coeff_per_k': must be in")) << bad.err;
  EXPECT_FALSE(fs::exists(path("bad.json")));

  // A flux map records no temperature: --magnet-reference-c states it,
  // else the export at another temperature names what is missing.
  const std::string map = std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_fluxmap_measured.csv";
  const std::string fit_map = "fit --map " + map + " --pole-pairs 2 --serial BALDOR-MAGNET-1 --magnet-temp-coeff-per-k -0.0011 ";
  ASSERT_EQ(RunFluxcal(fit_map + "--magnet-reference-c 60 --out " + path("map60.json")).code, 0);
  const RunResult at = RunFluxcal("export " + path("map60.json") + " --table mtpa --magnet-temp-c 120 --format h --out " +
                                  path("map120.h") + " --json");
  ASSERT_EQ(at.code, 0) << at.err;
  const nlohmann::json aj = nlohmann::json::parse(at.out);
  EXPECT_EQ(aj["magnet_temperature"]["at_c"], 120.0) << at.out;
  EXPECT_EQ(aj["magnet_temperature"]["reference_c"], 60.0) << at.out;
  EXPECT_EQ(aj["magnet_temperature"]["reference_spread_k"], 0.0) << at.out;
  EXPECT_NEAR(aj["magnet_temperature"]["psi_pm_scale"].get<double>(), 1 - 0.0011 * 60, 1e-12) << at.out;
  EXPECT_TRUE(Has(ReadFile(path("map120.h")), "MAGNET_REFERENCE_C")) << ReadFile(path("map120.h")).substr(0, 3000);
  const RunResult no_ref_fit = RunFluxcal(fit_map + "--out " + path("map.json"));
  ASSERT_EQ(no_ref_fit.code, 0) << no_ref_fit.err;
  const RunResult no_ref = RunFluxcal("export " + path("map.json") + " --table mtpa --magnet-temp-c 120 --out " +
                                      path("x.csv"));
  EXPECT_EQ(no_ref.code, 2);
  EXPECT_TRUE(Has(no_ref.err, "flag --magnet-temp-c: the calibration of BALDOR-MAGNET-1 states no magnet temperature "
                              "of its flux map")) << no_ref.err;
  EXPECT_FALSE(Has(no_ref.err, "no magnet temperature coefficient")) << no_ref.err;
  const RunResult bad_flag = RunFluxcal(fit_map + "--magnet-reference-c 400 --out " + path("y.json"));
  EXPECT_EQ(bad_flag.code, 2);
  EXPECT_TRUE(Has(bad_flag.err, "flag --magnet-reference-c: must be")) << bad_flag.err;
  fs::remove_all(dir);
}

}  // namespace
}  // namespace fluxcal::e2e
