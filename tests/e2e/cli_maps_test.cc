// Flux maps in the field's other conventions, end to end through `fluxcal`
// (issue: a SyR-e map, swapped columns and mWb all fitted with exit 0 and
// reported "pass"; every map fit's report showed "RMS relative residual
// 0.000 %"). Each file is made here from the measured map in data/real:
//   - SyR-e's axes (Id, Iq, Fd, Fq; the magnet on -q): detected, or given
//     with --convention syre, it fits to the same calibration as the map
//     itself; read as fluxcal's axes it is refused naming SyR-e;
//   - the psi columns exchanged: refused as such;
//   - the flux in mWb under psi_d_Vs: refused with the hint, accepted with
//     --units mWb with the right psi_pm;
//   - rms currents: --current rms gives the map's psi_pm and error;
//   - the report of a map fit shows its flux error over the nodes, and a
//     map fit too stiff for the map fails the verdict.
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "tests/e2e/fluxcal_run.h"

namespace {

namespace fs = std::filesystem;

using Result = fluxcal::e2e::RunResult;
// Runs the binary: stdout and stderr captured apart.
Result Fluxcal(const std::string& args) { return fluxcal::e2e::RunFluxcal(args); }

struct Node {
  double id, iq, pd, pq;
};

// The measured map's raw nodes (data/real/baldor_fluxmap_measured.csv).
std::vector<Node> Measured() {
  std::ifstream in(std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_fluxmap_measured.csv");
  std::string line;
  std::getline(in, line);
  std::vector<Node> nodes;
  while (std::getline(in, line)) {
    Node n;
    if (std::sscanf(line.c_str(), "%lf,%lf,%lf,%lf", &n.id, &n.iq, &n.pd, &n.pq) == 4) nodes.push_back(n);
  }
  EXPECT_EQ(nodes.size(), 567u);
  return nodes;
}

void Write(const std::string& path, const std::string& header,
           const std::function<std::array<double, 4>(const Node&)>& f) {
  std::ofstream out(path);
  out << header << "\n";
  char buf[160];
  for (const auto& n : Measured()) {
    const auto v = f(n);
    std::snprintf(buf, sizeof buf, "%.17g,%.17g,%.17g,%.17g\n", v[0], v[1], v[2], v[3]);
    out << buf;
  }
}

TEST(CliMaps, ForeignConventionsAreReadOrRefusedWithTheirCause) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_e2e_conv_");
  auto path = [&](const char* name) { return (dir / name).string(); };
  Write(path("native.csv"), "id_A,iq_A,psi_d_Vs,psi_q_Vs",
        [](const Node& n) { return std::array<double, 4>{n.id, n.iq, n.pd, n.pq}; });
  // SyR-e's frame: d_syre = q, q_syre = -d (fluxcal d = -q_syre, q = d_syre).
  Write(path("syre.csv"), "Id,Iq,Fd,Fq", [](const Node& n) { return std::array<double, 4>{n.iq, -n.id, n.pq, -n.pd}; });
  Write(path("swapped.csv"), "id_A,iq_A,psi_q_Vs,psi_d_Vs",
        [](const Node& n) { return std::array<double, 4>{n.id, n.iq, n.pd, n.pq}; });
  Write(path("mwb.csv"), "id_A,iq_A,psi_d_Vs,psi_q_Vs",
        [](const Node& n) { return std::array<double, 4>{n.id, n.iq, 1e3 * n.pd, 1e3 * n.pq}; });
  Write(path("rms.csv"), "id_A,iq_A,psi_d_Vs,psi_q_Vs", [](const Node& n) {
    return std::array<double, 4>{n.id / std::sqrt(2.0), n.iq / std::sqrt(2.0), n.pd, n.pq};
  });
  const std::string fit = "fit --pole-pairs 2 --serial BALDOR-CONV-1 --json --map ";

  const Result native = Fluxcal(fit + path("native.csv") + " --out " + path("native.json"));
  ASSERT_EQ(native.code, 0) << native.err;
  const auto nj = nlohmann::json::parse(native.out);
  const double psi_pm = nj["psi_pm_wb"];
  const double rms = nj["map"]["rms_relative"];
  EXPECT_NEAR(psi_pm, 0.4441, 0.002) << "psi_pm of the measured map (its node at zero current 0.4441 Wb), Wb";
  EXPECT_LT(rms, 0.01) << "RMS flux error over the map's nodes / max |psi|";
  EXPECT_EQ(nj["map"]["nodes"], 567);
  EXPECT_EQ(nj["fit"]["flux_nodes"], 567) << "the calibration itself carries the map fit's error";
  EXPECT_EQ(nj["fit"]["flux_rms_relative"], nj["map"]["rms_relative"]) << "one figure, one home";
  EXPECT_EQ(nj["map"]["convention"]["axes"], "fluxcal");
  EXPECT_EQ(nj["map"]["convention"]["axes_source"], "detected");
  EXPECT_NE(native.err.find("axes fluxcal (detected"), std::string::npos) << native.err;

  // SyR-e's axes, detected and given: the same calibration (the conversion
  // is exact, so the fit sees the same numbers).
  for (const std::string flags : {"", " --convention syre"}) {
    const Result syre = Fluxcal(fit + path("syre.csv") + flags + " --force --out " + path("syre.json"));
    ASSERT_EQ(syre.code, 0) << flags << ": " << syre.err;
    const auto sj = nlohmann::json::parse(syre.out);
    EXPECT_NEAR(sj["psi_pm_wb"].get<double>(), psi_pm, 1e-9 * psi_pm) << flags << ": psi_pm, Wb";
    EXPECT_NEAR(sj["map"]["rms_relative"].get<double>(), rms, 1e-9) << flags;
    EXPECT_EQ(sj["model"], nj["model"]) << flags;
    EXPECT_EQ(sj["map"]["convention"]["axes"], "syre") << flags;
    EXPECT_EQ(sj["map"]["convention"]["axes_source"], flags.empty() ? "detected" : "flag");
    EXPECT_NE(syre.err.find("id = -Iq, iq = Id, psi_d = -Fq, psi_q = Fd"), std::string::npos) << syre.err;
  }
  const Result as_fluxcal = Fluxcal(fit + path("syre.csv") + " --convention fluxcal --out " + path("x.json"));
  EXPECT_EQ(as_fluxcal.code, 1);
  EXPECT_NE(as_fluxcal.err.find("syre.csv:285: field 'Fq': the magnet lies on the -q axis"), std::string::npos)
      << as_fluxcal.err;
  EXPECT_NE(as_fluxcal.err.find("a SyR-e map"), std::string::npos) << as_fluxcal.err;
  EXPECT_NE(as_fluxcal.err.find("give --convention syre"), std::string::npos) << as_fluxcal.err;

  // Swapped flux columns.
  const Result swapped = Fluxcal(fit + path("swapped.csv") + " --out " + path("x.json"));
  EXPECT_EQ(swapped.code, 1);
  EXPECT_NE(swapped.err.find("the psi_d and psi_q columns look exchanged"), std::string::npos) << swapped.err;
  EXPECT_FALSE(fs::exists(path("x.json"))) << "nothing written for a refused map";

  // mWb under a Vs header.
  const Result mwb = Fluxcal(fit + path("mwb.csv") + " --out " + path("x.json"));
  EXPECT_EQ(mwb.code, 1);
  EXPECT_NE(mwb.err.find("psi_pm 444.1 Wb"), std::string::npos) << mwb.err;
  EXPECT_NE(mwb.err.find("is the flux in mWb? give --units mWb"), std::string::npos) << mwb.err;
  const Result mwb_ok = Fluxcal(fit + path("mwb.csv") + " --units mWb --out " + path("mwb.json"));
  ASSERT_EQ(mwb_ok.code, 0) << mwb_ok.err;
  EXPECT_NEAR(nlohmann::json::parse(mwb_ok.out)["psi_pm_wb"].get<double>(), psi_pm, 1e-6 * psi_pm) << "psi_pm, Wb";

  // rms-valued currents.
  const Result r = Fluxcal(fit + path("rms.csv") + " --current rms --out " + path("rms.json"));
  ASSERT_EQ(r.code, 0) << r.err;
  const auto rj = nlohmann::json::parse(r.out);
  EXPECT_NEAR(rj["psi_pm_wb"].get<double>(), psi_pm, 1e-6 * psi_pm) << "psi_pm, Wb";
  EXPECT_NEAR(rj["map"]["rms_relative"].get<double>(), rms, 1e-4);
  EXPECT_EQ(rj["region"]["id_min_a"], -20.0) << "currents back at their peak values, A";

  // Bad flag values and flags without a map: usage errors.
  EXPECT_EQ(Fluxcal(fit + path("native.csv") + " --convention syr --out " + path("x.json")).code, 2);
  EXPECT_EQ(Fluxcal(fit + path("native.csv") + " --units kWb --out " + path("x.json")).code, 2);
  const Result no_map = Fluxcal("fit " + path("native.json") + " --convention syre --out " + path("x.json"));
  EXPECT_EQ(no_map.code, 2);
  EXPECT_NE(no_map.err.find("need --map"), std::string::npos) << no_map.err;

  // compare reads a map the same way: the SyR-e file against the
  // calibration gives what the native file gives.
  const Result c1 = Fluxcal("compare " + path("native.json") + " " + path("native.csv") + " --json");
  const Result c2 = Fluxcal("compare " + path("native.json") + " " + path("syre.csv") + " --json");
  ASSERT_EQ(c1.code, 0) << c1.err;
  ASSERT_EQ(c2.code, 0) << c2.err;
  const auto j1 = nlohmann::json::parse(c1.out), j2 = nlohmann::json::parse(c2.out);
  EXPECT_EQ(j2["convention"]["axes"], "syre");
  EXPECT_EQ(j1["nodes"], j2["nodes"]);
  EXPECT_EQ(j1["rms_relative"], j2["rms_relative"]);
  EXPECT_EQ(Fluxcal("compare " + path("native.json") + " " + path("mwb.csv")).code, 1);

  // The report: the map fit's flux error, not an inductance residual.
  const Result rep = Fluxcal("report " + path("native.json") + " --out " + path("native.html") + " --json");
  ASSERT_EQ(rep.code, 0) << rep.err;
  EXPECT_EQ(nlohmann::json::parse(rep.out)["verdict"], "pass");
  std::ifstream page(path("native.html"));
  const std::string html((std::istreambuf_iterator<char>(page)), std::istreambuf_iterator<char>());
  EXPECT_NE(html.find("flux error against the map</th><td>RMS 0."), std::string::npos);
  EXPECT_NE(html.find("over 567 nodes"), std::string::npos);
  EXPECT_EQ(html.find("RMS relative residual"), std::string::npos) << "a map fit has no identified inductances";
  // A model too stiff for the map: its flux error fails the verdict.
  ASSERT_EQ(Fluxcal(fit + path("native.csv") + " --model poly2 --out " + path("stiff.json")).code, 0);
  const Result stiff = Fluxcal("report " + path("stiff.json") + " --out " + path("stiff.html") + " --json");
  ASSERT_EQ(stiff.code, 0) << stiff.err;
  const std::string verdict = nlohmann::json::parse(stiff.out)["verdict"];
  EXPECT_EQ(verdict.rfind("fail: flux error against the map", 0), 0u) << verdict;
  fs::remove_all(dir);
}

}  // namespace
