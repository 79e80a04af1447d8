// The command line end to end: simulate -> identify -> fit -> query ->
// export -> diagnose, each with --json parsed as a single document, and the
// error path of bad input.
#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "tests/e2e/fluxcal_run.h"

namespace {

namespace fs = std::filesystem;

using Run = fluxcal::e2e::RunResult;
// Runs the binary; stdout and stderr captured.
Run Fluxcal(const std::string& args) { return fluxcal::e2e::RunFluxcal(args); }

nlohmann::json Json(const Run& r) {
  EXPECT_EQ(r.code, 0) << r.out;
  return nlohmann::json::parse(r.out);   // throws if not exactly one document
}

TEST(Cli, EndToEnd) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_e2e_");
  const std::string set = (dir / "set").string();
  auto sim = Json(Fluxcal("simulate --out " + set + " --seed 5 --serial IPM-E2E-1 --effects dead_time_s=1.5e-6 --json"));
  EXPECT_EQ(sim["serial"], "IPM-E2E-1");
  ASSERT_TRUE(fs::exists(set + "/manifest.json"));
  ASSERT_TRUE(fs::exists(set + ".truth.json"));

  auto valid = Json(Fluxcal("validate " + set + " --json"));
  EXPECT_TRUE(valid["valid"].get<bool>());
  EXPECT_EQ(valid["points"], 40);
  auto id = Json(Fluxcal("identify " + set + " --json"));
  ASSERT_EQ(id["points"].size(), 40u);
  EXPECT_GT(id["points"][0]["ld_h"].get<double>(), 1e-4);
  auto paper = Json(Fluxcal("identify " + set + " --method paper --json"));
  EXPECT_TRUE(paper["points"][0]["ldq_h"].is_null());
  const auto csv = Fluxcal("identify " + set + " --csv");
  EXPECT_EQ(csv.out.rfind("point,id_a,iq_a,speed_rpm,ld_h,lq_h,ldq_h,r_hf_ohm", 0), 0u);

  const std::string cal = (dir / "cal.json").string();
  auto fit = Json(Fluxcal("fit " + set + " --out " + cal + " --json"));
  EXPECT_EQ(fit["format"], "fluxcal.calibration.v1");
  auto q = Json(Fluxcal("query " + cal + " --id-a -20 --iq-a 40 --json"));
  EXPECT_GT(q["torque_nm"].get<double>(), 0.0);
  const auto grid = Fluxcal("query " + cal + " --grid -100:0:3,0:100:3");
  EXPECT_EQ(std::count(grid.out.begin(), grid.out.end(), '\n'), 10);

  // The printed sha256 is the file's (what sha256sum says); the checksums
  // over the values are printed as payload_crc32 / payload_sha256.
  const bool have_sha256sum = std::system("sha256sum --version > /dev/null 2>&1") == 0;
  for (const char* fmt : {"csv", "json", "h", "cdfx", "dcm"}) {
    const std::string out = (dir / (std::string("mtpa.") + fmt)).string();
    auto e = Json(Fluxcal("export " + cal + " --table mtpa --format " + fmt + " --points 8 --out " + out + " --json"));
    EXPECT_EQ(e["sha256"].get<std::string>().size(), 64u) << fmt;
    EXPECT_EQ(e["payload_sha256"].get<std::string>().size(), 64u) << fmt;
    EXPECT_NE(e["sha256"], e["payload_sha256"]) << fmt;
    EXPECT_EQ(e["release_state"], "unknown (local export, release store not consulted)") << fmt;
    EXPECT_TRUE(fs::file_size(out) > 100) << fmt;
    if (have_sha256sum) {
      FILE* p = popen(("sha256sum " + out).c_str(), "r");
      char sum[65] = {};
      ASSERT_EQ(fread(sum, 1, 64, p), 64u);
      pclose(p);
      EXPECT_EQ(e["sha256"].get<std::string>(), std::string(sum)) << fmt;
    }
  }
  {
    // --ctype float; an unknown ctype and a current limit beyond the
    // measured one are refused unless --allow-extrapolation.
    const std::string out = (dir / "mtpa_float.h").string();
    auto h = Json(Fluxcal("export " + cal + " --table mtpa --format h --ctype float --points 8 --out " + out + " --json"));
    // --points 8: at most 8 rows at round torques, 0 among them (an odd count).
    const int rows = h["cells"].get<int>();
    EXPECT_LE(rows, 8);
    EXPECT_EQ(rows % 2, 1);
    std::ifstream in(out);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    EXPECT_NE(text.find("static const float fluxcal_mtpa_id_a[" + std::to_string(rows) + "]"), std::string::npos);
    EXPECT_EQ(Fluxcal("export " + cal + " --table mtpa --format h --ctype half --out " + out).code, 2);
    // (--force: `out` holds the table above; the overwrite rule, docs/cli.md.)
    EXPECT_EQ(Fluxcal("export " + cal + " --table mtpa --format csv --i-max-a 1000 --force --out " + out).code, 2);
    auto x = Json(Fluxcal("export " + cal + " --table mtpa --format csv --points 8 --i-max-a 1000 --allow-extrapolation --force --out " +
                          out + " --json"));
    EXPECT_GT(x["extrapolated_cells"].get<int>(), 0);
  }

  // Signed export: keygen, export --sign-key, verify; a changed byte or
  // another key fails verification.
  const std::string prefix = (dir / "signing").string();
  auto kg = Json(Fluxcal("admin keygen --out " + prefix + " --json"));
  EXPECT_EQ(kg["key_id"].get<std::string>().size(), 16u);
  EXPECT_EQ(Fluxcal("admin keygen --out " + prefix).code, 1);   // never overwrites a key
  const std::string table = (dir / "signed.dcm").string();
  auto se = Json(Fluxcal("export " + cal + " --table mtpa --format dcm --points 8 --out " + table + " --sign-key " +
                         prefix + ".key --json"));
  EXPECT_EQ(se["signature"], table + ".sig");
  auto ok = Json(Fluxcal("verify " + table + " --pubkey " + prefix + ".pub --json"));
  EXPECT_TRUE(ok["valid"].get<bool>());
  EXPECT_EQ(ok["key_id"], kg["key_id"]);
  {
    std::ofstream(table, std::ios::app) << " ";
    const auto bad = Fluxcal("verify " + table + " --pubkey " + prefix + ".pub --json");
    EXPECT_EQ(bad.code, 1);
    EXPECT_NE(bad.out.find("changed after signing"), std::string::npos) << bad.out;
  }
  Json(Fluxcal("admin keygen --out " + prefix + "2 --json"));
  // The tampered table replaced (--force: the overwrite rule) by a fresh signed one.
  Json(Fluxcal("export " + cal + " --table mtpa --format dcm --points 8 --force --out " + table + " --sign-key " + prefix +
               ".key --json"));
  const auto other = Fluxcal("verify " + table + " --pubkey " + prefix + "2.pub --json");
  EXPECT_EQ(other.code, 1);
  EXPECT_NE(other.out.find("not by this key"), std::string::npos) << other.out;

  auto diag = Json(Fluxcal("diagnose " + set + " --json"));
  EXPECT_EQ(diag["format"], "fluxcal.diagnosis.v1");
  ASSERT_GE(diag["findings"].size(), 1u);
  EXPECT_EQ(diag["findings"][0]["effect"], "dead_time");
  fs::remove_all(dir);
  fs::remove(set + ".truth.json");
}

// Replay through the twin with a fitted calibration: a clean twin set is
// reproduced to its sensor noise, open loop and closed loop (the twin's
// default bench controller is what the replay assumes by default).
TEST(Cli, ReplayReproducesACleanSet) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_e2e_replay_");
  const std::string set = (dir / "set").string(), cal = (dir / "cal.json").string();
  Json(Fluxcal("simulate --out " + set + " --seed 6 --serial IPM-E2E-2 --json"));
  Json(Fluxcal("fit " + set + " --out " + cal + " --json"));
  for (const char* mode : {"", " --closed-loop"}) {
    auto r = Json(Fluxcal("replay " + set + " --calibration " + cal + mode + " --json"));
    EXPECT_EQ(r["points"].size(), 40u) << mode;
    // 0.05 A noise and 0.12 A ADC steps per phase on the twin's sensors.
    EXPECT_LT(r["residual_rms_a"].get<double>(), 0.15) << mode;
  }
  EXPECT_EQ(Fluxcal("replay " + set).code, 2);   // --calibration missing
  fs::remove_all(dir);
  fs::remove(set + ".truth.json");
}

TEST(Cli, BadInputNamesTheFile) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_e2e_bad_");
  std::ofstream(dir / "manifest.json") << "{\"format\": \"fluxcal.recording.v1\", \"serial\": \"bad serial\"}";
  const auto id = Fluxcal("identify " + dir.string() + " --json");
  const std::string out = id.out + id.err;
  EXPECT_EQ(id.code, 1);
  EXPECT_NE(out.find("manifest.json"), std::string::npos) << out;
  EXPECT_NE(out.find("field 'serial'"), std::string::npos) << out;
  // validate: the same message as one JSON document, exit 1.
  const auto v = Fluxcal("validate " + dir.string() + " --json");
  EXPECT_EQ(v.code, 1);
  const auto vj = nlohmann::json::parse(v.out);
  EXPECT_FALSE(vj["valid"].get<bool>());
  EXPECT_NE(vj["error"].get<std::string>().find("field 'serial'"), std::string::npos) << v.out;
  EXPECT_EQ(Fluxcal("nosuchcommand").code, 2);
  EXPECT_EQ(Fluxcal("identify " + dir.string() + " --bogus").code, 2);
  fs::remove_all(dir);
}

// Issue 24: `fluxcal admin verify-db --db typo.db` created an empty store
// and printed "intact". The commands that only read a store refuse a path
// that does not exist (and an empty file), naming the flag and the path,
// and create nothing.
TEST(Cli, ReadOnlyAdminCommandsRefuseAMissingStore) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_e2e_typo_");
  const std::string typo = (dir / "typo.db").string();
  for (const std::string cmd : {"admin verify-db --db ", "admin verify-db --json --db sqlite:", "admin hash --db ",
                                "admin anchor --db "}) {
    const auto r = Fluxcal(cmd + typo);
    const std::string out = r.out + r.err;
    EXPECT_EQ(r.code, 1) << cmd << ": " << out;
    EXPECT_NE(out.find("flag --db: sqlite: no store at '" + typo + "': the file does not exist"), std::string::npos)
        << cmd << ": " << out;
    EXPECT_EQ(out.find("intact"), std::string::npos) << cmd << ": " << out;
    EXPECT_FALSE(fs::exists(typo)) << cmd << " created the store it was asked to read";
  }
  std::ofstream(typo).close();   // an empty file is not a store either, and stays empty
  EXPECT_EQ(Fluxcal("admin verify-db --db " + typo).code, 1);
  EXPECT_EQ(fs::file_size(typo), 0u);
  EXPECT_EQ(Fluxcal("admin verify-db --db " + typo + " --anchor " + (dir / "none.jsonl").string()).code, 1);
  fs::remove_all(dir);
}

// Flux maps in and out: fit a calibration to the published map of a real
// machine, compare it with that map, export it as a map and an inverse map,
// and compare it with its own export; each --json output is one document.
TEST(Cli, FluxMapsInAndOut) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_e2e_maps_");
  const std::string measured = std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_fluxmap_measured.csv";
  const std::string cal = (dir / "cal.json").string(), map = (dir / "map.csv").string(),
                    inv = (dir / "inv.csv").string();
  auto fit = Json(Fluxcal("fit --map " + measured + " --pole-pairs 2 --serial BALDOR-MAP-1 --out " + cal + " --json"));
  EXPECT_EQ(fit["serial"], "BALDOR-MAP-1");
  EXPECT_EQ(fit["pole_pairs"], 2);
  EXPECT_EQ(fit["map"]["nodes"], 567);
  EXPECT_LT(fit["map"]["rms_relative"].get<double>(), 0.01);
  EXPECT_EQ(Fluxcal("fit --map " + measured + " --out " + cal).code, 2);   // --pole-pairs missing

  // Against the measured map over the region the bench samples.
  auto c = Json(Fluxcal("compare " + cal + " " + measured + " --region -18:0,0:24 --json"));
  EXPECT_EQ(c["nodes"], 130);
  EXPECT_EQ(c["columns"], "raw");
  EXPECT_EQ(c["region"]["source"], "flag");
  for (const char* k : {"rms_relative", "max_relative", "rms_wb", "max_wb", "rms_d_wb", "rms_q_wb", "psi_scale_wb"}) {
    ASSERT_TRUE(c[k].is_number()) << k;
  }
  EXPECT_LT(c["rms_relative"].get<double>(), 0.01);
  EXPECT_LE(c["rms_relative"].get<double>(), c["max_relative"].get<double>());
  EXPECT_TRUE(c["worst"]["id_a"].is_number());
  EXPECT_TRUE(c["worst"]["error_wb"].is_number());
  auto sym = Json(Fluxcal("compare " + cal + " " + measured + " --sym --json"));
  EXPECT_EQ(sym["columns"], "sym");
  EXPECT_EQ(sym["region"]["source"], "measured");
  EXPECT_EQ(sym["nodes"], 294);   // id -20..20 A, iq 0..26 A: 21 x 14 nodes

  // Export, never overwriting without --force.
  auto e = Json(Fluxcal("map export " + cal + " --out " + map + " --json"));
  EXPECT_EQ(e["rows"], 441);
  EXPECT_EQ(e["extrapolated"], 0);
  EXPECT_EQ(e["sha256"].get<std::string>().size(), 64u);
  EXPECT_EQ(Fluxcal("map export " + cal + " --out " + map).code, 1);
  auto e2 = Json(Fluxcal("map export " + cal + " --out " + map + " --grid -20:0:11,0:26:14 --force --json"));
  EXPECT_EQ(e2["rows"], 154);
  auto self = Json(Fluxcal("compare " + cal + " " + map + " --json"));
  EXPECT_EQ(self["nodes"], 154);
  EXPECT_LT(self["rms_relative"].get<double>(), 1e-12);
  auto i = Json(Fluxcal("map export " + cal + " --out " + inv + " --inverse --json"));
  EXPECT_EQ(i["kind"], "inverse");
  EXPECT_EQ(i["rows"], 441);
  EXPECT_GT(i["valid"].get<int>(), 200);
  EXPECT_EQ(i["valid"].get<int>() + i["invalid"].get<int>(), 441);
  {
    std::ifstream in(inv);
    std::string header;
    std::getline(in, header);
    EXPECT_EQ(header, "psi_d_Vs,psi_q_Vs,id_A,iq_A,valid");
  }
  EXPECT_EQ(Fluxcal("map export " + cal + " --out " + inv + " --psi-grid 0:1:3,0:1:3 --force").code, 2);
  EXPECT_EQ(Fluxcal("map export " + cal + " --out " + inv + " --inverse --grid 0:1:3,0:1:3 --force").code, 2);

  // Bad input: exit 1, the message names file, line and field.
  const std::string bad = (dir / "bad.csv").string();
  std::ofstream(bad) << "id_A,iq_A,psi_d_Vs,psi_q_Vs\n0,0,0.44,0\n0,2,0.45,x\n";
  const auto refused = Fluxcal("compare " + cal + " " + bad + " --json");
  const std::string out = refused.out + refused.err;
  EXPECT_EQ(refused.code, 1);
  EXPECT_NE(out.find(bad + ":3: field 'psi_q_Vs': expected a number, got 'x'"), std::string::npos) << out;
  EXPECT_EQ(Fluxcal("compare " + cal + " " + measured + " --region 0:1").code, 2);
  fs::remove_all(dir);
}

// Both torque directions from a bench that measured one (the issue's
// repro, data/real): the fit uses the machine's symmetry, the braking half
// agrees with the machine's measured map, queries say where a point lies
// and whether it is valid, and the exported table flags its braking rows
// "by symmetry". Asked for an asymmetric model by name, the other half is
// extrapolated.
TEST(Cli, BothTorqueDirectionsFromOneMeasuredHalf) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_e2e_sym_");
  const std::string real = std::string(FLUXCAL_SOURCE_DIR) + "/data/real";
  const std::string map = real + "/baldor_fluxmap_measured.csv", cal = (dir / "c.json").string();
  Json(Fluxcal("fit " + real + "/baldor_eol --out " + cal + " --json"));
  auto braking = Json(Fluxcal("compare " + cal + " " + map + " --region -18:0,-24:0 --json"));
  auto motoring = Json(Fluxcal("compare " + cal + " " + map + " --region -18:0,0:24 --json"));
  EXPECT_EQ(braking["nodes"], 130);
  EXPECT_LT(braking["rms_relative"].get<double>(), 0.005) << "62 % with the asymmetric model of one half";
  EXPECT_LT(motoring["rms_relative"].get<double>(), 0.005);

  auto q = Json(Fluxcal("query " + cal + " --id-a -10 --iq-a -12 --json"));
  EXPECT_EQ(q["region"], "by_symmetry");
  EXPECT_EQ(q["extrapolated"], false);
  EXPECT_EQ(q["valid"], true);
  EXPECT_EQ(q["invalid_reason"], "");
  EXPECT_GT(q["ldd_h"].get<double>(), 0.0) << "was -9.5 mH, reported as measured";
  EXPECT_EQ(Json(Fluxcal("query " + cal + " --id-a -10 --iq-a 12 --json"))["region"], "measured");
  EXPECT_EQ(Json(Fluxcal("query " + cal + " --id-a -10 --iq-a 40 --json"))["region"], "extrapolated");
  const auto text = Fluxcal("query " + cal + " --id-a -10 --iq-a -12");
  EXPECT_NE(text.out.find("(by symmetry"), std::string::npos) << text.out;
  const auto csv = Fluxcal("query " + cal + " --grid -10:-10:1,-12:12:2");
  EXPECT_NE(csv.out.find("torque_nm_std,extrapolated,region,valid\n"), std::string::npos) << csv.out;
  EXPECT_NE(csv.out.find(",0,by_symmetry,1\n"), std::string::npos) << csv.out;
  EXPECT_NE(csv.out.find(",0,measured,1\n"), std::string::npos) << csv.out;

  const std::string table = (dir / "mtpa.csv").string();
  Json(Fluxcal("export " + cal + " --table mtpa --format csv --points 5 --out " + table + " --json"));
  {
    std::ifstream in(table);
    std::string line, header;
    std::vector<std::string> rows;
    while (std::getline(in, line)) {
      if (line.empty() || line[0] == '#') continue;
      if (header.empty()) header = line; else rows.push_back(line);
    }
    EXPECT_EQ(header, "torque_nm,id_a,iq_a,clamped,extrapolated,by_symmetry,not_positive_definite");
    ASSERT_EQ(rows.size(), 5u);
    for (size_t k = 0; k < rows.size(); ++k) {
      const bool negative = rows[k][0] == '-';
      EXPECT_EQ(rows[k].substr(rows[k].size() - 8), negative ? ",0,0,1,0" : ",0,0,0,0") << rows[k];
    }
  }

  const std::string asym = (dir / "asym.json").string();
  Json(Fluxcal("fit " + real + "/baldor_eol --model smooth-asym --out " + asym + " --json"));
  auto x = Json(Fluxcal("query " + asym + " --id-a -10 --iq-a -12 --json"));
  EXPECT_EQ(x["region"], "extrapolated");
  EXPECT_EQ(x["extrapolated"], true);
  fs::remove_all(dir);
}

}  // namespace
