// Tests of the recording-set reader/writer: the three example sets read, a
// written set reads back, and every malformed input yields an error naming
// the file, the line and the field.
#include "io/recording_set.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <numbers>
#include <random>
#include <sstream>

#include "gtest/gtest.h"
#include "io/csv.h"
#include "tests/support/shared_examples.h"

namespace fluxcal::io {
namespace {

namespace fs = std::filesystem;

// A small valid set: 2 locked points of 200 samples at 10 kHz with 500 Hz
// injection (10 periods) plus steady_state and hf_results tables.
RecordingSet MakeSet(size_t samples = 200) {
  RecordingSet s;
  Manifest& m = s.manifest;
  m.serial = "IPM-TEST-001";
  m.motor.pole_pairs = 4;
  m.motor.rs_ohm = 0.011;
  m.motor.psi_pm_wb = 0.0089;
  m.drive.udc_v = 50.0;
  m.drive.f_pwm_hz = 10000.0;
  m.drive.f_sample_hz = 10000.0;
  m.drive.dead_time_s = 1e-6;
  m.drive.dead_time_compensated = true;
  m.injection = InjectionInfo{"rotating", 5.0, 500.0};
  for (int p = 0; p < 2; ++p) {
    PointSpec ps;
    ps.id = "p00" + std::to_string(p);
    ps.file = "points/" + ps.id + ".csv";
    ps.id_ref_a = -20.0 * p;
    ps.iq_ref_a = 40.0;
    ps.temperature_c = 25.0;
    m.points.push_back(ps);
    Waveform w;
    for (size_t k = 0; k < samples; ++k) {
      const double t = static_cast<double>(k) / m.drive.f_sample_hz;
      const double ph = 2 * std::numbers::pi * 500.0 * t;
      w.t_s.push_back(t);
      w.ia_a.push_back(10 * std::cos(ph));
      w.ib_a.push_back(10 * std::cos(ph - 2.0944));
      w.ic_a.push_back(10 * std::cos(ph + 2.0944));
      w.theta_e_rad.push_back(0.3 * p);
      w.ualpha_ref_v.push_back(5 * std::cos(ph));
      w.ubeta_ref_v.push_back(5 * std::sin(ph));
      w.udc_v.push_back(k % 2 ? 50.01 : std::nan(""));
    }
    s.waveforms.push_back(w);
  }
  m.steady_state = "steady_state.csv";
  s.steady_state.push_back({-20, 60, 1000, -10.5, 20.25, 8.5, 25});
  s.steady_state.push_back({0, 40, 2000, -12.5, 22.25, std::nullopt, std::nullopt});
  m.hf_results = "hf_results.csv";
  s.hf_results.push_back({-20, 40, 0, 1.8e-4, 3.5e-4, -1e-5, 25});
  s.hf_results.push_back({0, 0, 0, 1.9e-4, 3.7e-4, std::nullopt, std::nullopt});
  return s;
}

class RecordingSetTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("fluxcal_io_test_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    ASSERT_TRUE(WriteRecordingSet(dir_.string(), MakeSet()).ok());
  }
  void TearDown() override { fs::remove_all(dir_); }

  std::string Read(const std::string& rel) {
    std::ifstream f(dir_ / rel);
    std::stringstream ss;
    ss << f.rdbuf();
    return ss.str();
  }
  void Write(const std::string& rel, const std::string& text) {
    std::ofstream f(dir_ / rel, std::ios::trunc);
    f << text;
  }
  // Replaces the first occurrence of `from` in file `rel`.
  void Replace(const std::string& rel, const std::string& from, const std::string& to) {
    std::string t = Read(rel);
    const auto pos = t.find(from);
    ASSERT_NE(pos, std::string::npos) << from << " not in " << rel;
    t.replace(pos, from.size(), to);
    Write(rel, t);
  }
  // Replaces line `line_no` (1-based) of a file.
  void ReplaceLine(const std::string& rel, size_t line_no, const std::string& line) {
    std::istringstream in(Read(rel));
    std::string out, l;
    size_t n = 0;
    while (std::getline(in, l)) {
      ++n;
      out += (n == line_no ? line : l) + "\n";
    }
    Write(rel, out);
  }
  // 1-based line of the first occurrence of `needle` in file `rel`.
  std::string LineOf(const std::string& rel, const std::string& needle) {
    const std::string t = Read(rel);
    const auto pos = t.find(needle);
    return rel + ":" + std::to_string(1 + std::count(t.begin(), t.begin() + pos, '\n'));
  }
  // Expects an error whose message contains every fragment.
  void ExpectError(absl::StatusCode code, const std::vector<std::string>& fragments) {
    auto r = ReadRecordingSet(dir_.string());
    ASSERT_FALSE(r.ok()) << "expected an error containing " << fragments[0];
    EXPECT_EQ(r.status().code(), code) << r.status();
    for (const auto& f : fragments) {
      EXPECT_NE(std::string(r.status().message()).find(f), std::string::npos)
          << "message '" << r.status().message() << "' lacks '" << f << "'";
    }
  }
  fs::path dir_;
};

TEST_F(RecordingSetTest, RoundTrip) {
  auto r = ReadRecordingSet(dir_.string());
  ASSERT_TRUE(r.ok()) << r.status();
  const RecordingSet want = MakeSet();
  EXPECT_EQ(r->manifest.serial, want.manifest.serial);
  EXPECT_EQ(r->manifest.motor.pole_pairs, 4);
  EXPECT_DOUBLE_EQ(*r->manifest.motor.rs_ohm, 0.011);
  EXPECT_EQ(*r->manifest.drive.dead_time_compensated, true);
  ASSERT_EQ(r->manifest.points.size(), 2u);
  ASSERT_EQ(r->waveforms.size(), 2u);
  ASSERT_EQ(r->waveforms[1].size(), 200u);
  for (size_t k = 0; k < 200; ++k) {
    EXPECT_NEAR(r->waveforms[1].ia_a[k], want.waveforms[1].ia_a[k], 1e-7);
    EXPECT_NEAR(r->waveforms[1].t_s[k], want.waveforms[1].t_s[k], 1e-12);
    EXPECT_EQ(std::isnan(r->waveforms[1].udc_v[k]), k % 2 == 0);
  }
  EXPECT_NEAR(EffectiveUdc(*r, 0, 0), 50.0, 0);
  EXPECT_NEAR(EffectiveUdc(*r, 0, 1), 50.01, 1e-12);
  ASSERT_EQ(r->steady_state.size(), 2u);
  EXPECT_FALSE(r->steady_state[1].torque_nm.has_value());
  EXPECT_DOUBLE_EQ(*r->steady_state[0].torque_nm, 8.5);
  ASSERT_EQ(r->hf_results.size(), 2u);
  EXPECT_DOUBLE_EQ(*r->hf_results[0].ldq_h, -1e-5);
  EXPECT_FALSE(r->hf_results[1].ldq_h.has_value());
}

// One line of a file replaced: refused, naming the file, the line and the
// field (and what is wrong with it).
TEST_F(RecordingSetTest, BadLineNamesFileLineAndField) {
  struct Case {
    const char* name;
    const char* file;
    size_t line;
    const char* text;
    std::vector<std::string> fragments;
  };
  const Case cases[] = {
      {"non-numeric cell", "points/p001.csv", 41, "0.0039,x,1,1,0,0,0,50", {"p001.csv:41", "field 'ia_a'", "'x'"}},
      {"nan cell", "points/p000.csv", 5, "0.0003,1,nan,1,0,0,0,50", {"p000.csv:5", "field 'ib_a'"}},
      {"inf cell", "points/p000.csv", 6, "0.0004,1,1,inf,0,0,0,50", {"p000.csv:6", "field 'ic_a'"}},
      {"overflow cell", "points/p000.csv", 6, "0.0004,1,1,1e999,0,0,0,50", {"p000.csv:6", "field 'ic_a'"}},
      {"missing cell", "points/p000.csv", 7, "0.0005,1,1,1,0", {"p000.csv:7", "field 'ualpha_ref_v'"}},
      {"non-monotonic time", "points/p000.csv", 11, "0.0008,1,1,1,0,0,0,50",
       {"p000.csv:11", "field 't_s'", "not increasing"}},
      {"uneven time", "points/p000.csv", 11, "0.00092,1,1,1,0,0,0,50", {"p000.csv:11", "field 't_s'", "unevenly"}},
      {"steady-state bad cell", "steady_state.csv", 3, "0,40,fast,-12.5,22.25,,",
       {"steady_state.csv:3", "field 'speed_rpm'"}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    SetUp();
    ReplaceLine(c.file, c.line, c.text);
    ExpectError(absl::StatusCode::kInvalidArgument, c.fragments);
  }
}

// Text of a file replaced (a column, a manifest field): refused, naming
// the file (and the line, where line_of names what is on it) and the field.
TEST_F(RecordingSetTest, BadTextNamesFileAndField) {
  struct Case {
    const char* name;
    const char* file;
    const char* from;
    const char* to;
    const char* line_of;   // "": the fragments name the place themselves
    std::vector<std::string> fragments;
  };
  const Case cases[] = {
      {"missing column", "points/p000.csv", "theta_e_rad,", "", "", {"p000.csv:1", "field 'theta_e_rad'"}},
      {"unknown column", "points/p000.csv", "udc_v\n", "udc_v,extra_v\n", "", {"p000.csv:1", "field 'extra_v'"}},
      {"sample rate disagrees with the manifest", "manifest.json", "\"f_sample_hz\": 10000.0",
       "\"f_sample_hz\": 20000.0", "", {"p000.csv:3", "field 't_s'", "f_sample_hz"}},
      {"illegal serial", "manifest.json", "IPM-TEST-001", "IPM TEST/001", "\"serial\"", {"field 'serial'"}},
      {"empty serial", "manifest.json", "IPM-TEST-001", "", "", {"manifest.json", "field 'serial'"}},
      {"unknown format version", "manifest.json", "fluxcal.recording.v1", "fluxcal.recording.v9", "\"format\"",
       {"field 'format'", "v9"}},
      {"missing pole pairs", "manifest.json", "\"pole_pairs\": 4,", "", "",
       {"manifest.json", "field 'motor.pole_pairs'"}},
      {"wrong JSON type", "manifest.json", "\"amplitude_v\": 5.0", "\"amplitude_v\": \"five\"", "",
       {"manifest.json", "field 'injection.amplitude_v'"}},
      {"JSON syntax error", "manifest.json", "\"serial\":", "\"serial\"", "\"serial\"", {"syntax"}},
      {"path escaping the set", "manifest.json", "\"points/p001.csv\"", "\"../p001.csv\"", "",
       {"manifest.json", "field 'points[1].file'"}},
      {"duplicate point id", "manifest.json", "\"id\": \"p001\"", "\"id\": \"p000\"", "",
       {"manifest.json", "field 'points[1].id'", "duplicate"}},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    SetUp();
    Replace(c.file, c.from, c.to);
    std::vector<std::string> fragments = c.fragments;
    if (*c.line_of != '\0') fragments.insert(fragments.begin(), LineOf(c.file, c.line_of));
    ExpectError(absl::StatusCode::kInvalidArgument, fragments);
  }
}

TEST_F(RecordingSetTest, TooFewInjectionPeriods) {
  ASSERT_TRUE(WriteRecordingSet(dir_.string(), MakeSet(190)).ok());
  ExpectError(absl::StatusCode::kInvalidArgument, {"p000.csv", "field 't_s'", "injection periods"});
}

TEST_F(RecordingSetTest, MissingReferencedWaveform) {
  fs::remove(dir_ / "points/p001.csv");
  ExpectError(absl::StatusCode::kNotFound, {"manifest.json", "field 'points[1].file'", "p001.csv"});
}

TEST_F(RecordingSetTest, MissingSteadyStateFile) {
  fs::remove(dir_ / "steady_state.csv");
  ExpectError(absl::StatusCode::kNotFound, {"manifest.json", "field 'steady_state'"});
}

TEST_F(RecordingSetTest, MissingManifest) {
  fs::remove(dir_ / "manifest.json");
  ExpectError(absl::StatusCode::kNotFound, {"manifest.json"});
}

// The compatible extension "Magnet temperature coefficient"
// (docs/recording-format.md): motor.psi_pm_temp_coeff_per_k, optional,
// read back as written; a set without it reads as before.
TEST_F(RecordingSetTest, MagnetTempCoeffRoundTrips) {
  auto before = ReadRecordingSet(dir_.string());
  ASSERT_TRUE(before.ok()) << before.status();
  EXPECT_FALSE(before->manifest.motor.psi_pm_temp_coeff_per_k.has_value());
  EXPECT_EQ(Read("manifest.json").find("psi_pm_temp_coeff_per_k"), std::string::npos);
  RecordingSet set = MakeSet();
  set.manifest.motor.psi_pm_temp_coeff_per_k = -0.0011;
  ASSERT_TRUE(WriteRecordingSet(dir_.string(), set).ok());
  auto r = ReadRecordingSet(dir_.string());
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->manifest.motor.psi_pm_temp_coeff_per_k, -0.0011);
}

// A coefficient in %/K (-0.11), beyond any magnet (+0.01), or not a number:
// refused, naming the file, the line and the field.
TEST_F(RecordingSetTest, BadMagnetTempCoeffNamesFileAndField) {
  for (const std::string bad : {"-0.11", "0.01", "\"-0.1 %/K\""}) {
    SetUp();
    Replace("manifest.json", "\"pole_pairs\": 4", "\"pole_pairs\": 4,\n    \"psi_pm_temp_coeff_per_k\": " + bad);
    ExpectError(absl::StatusCode::kInvalidArgument,
                {LineOf("manifest.json", "psi_pm_temp_coeff_per_k"), "field 'motor.psi_pm_temp_coeff_per_k'",
                 bad[0] == '"' ? "expected a number" : "must be in [-0.005, 0.002]"});
  }
}

// The compatible extension "Rows a bench could not hold"
// (docs/recording-format.md): optional columns after the standard ones.
// A set without them is written exactly as the base format's (7 columns).
TEST_F(RecordingSetTest, SteadyStateWithoutExtensionWritesTheBaseHeader) {
  const std::string text = Read("steady_state.csv");
  EXPECT_EQ(text.substr(0, text.find('\n')), "id_a,iq_a,speed_rpm,ud_ref_v,uq_ref_v,torque_nm,temperature_c");
  auto r = ReadRecordingSet(dir_.string());
  ASSERT_TRUE(r.ok()) << r.status();
  for (const auto& row : r->steady_state) {
    EXPECT_FALSE(row.current_ripple_a || row.voltage_limited_share || row.controller_saturated_share);
  }
}

TEST_F(RecordingSetTest, SteadyStateExtensionRoundTrip) {
  RecordingSet set = MakeSet();
  set.steady_state[0].current_ripple_a = 0.125;
  set.steady_state[0].voltage_limited_share = 0.25;
  set.steady_state[0].controller_saturated_share = 1.0;
  set.steady_state[1].current_ripple_a = 3.5;   // the shares of row 2 unknown
  ASSERT_TRUE(WriteRecordingSet(dir_.string(), set).ok());
  const std::string text = Read("steady_state.csv");
  EXPECT_EQ(text.substr(0, text.find('\n')),
            "id_a,iq_a,speed_rpm,ud_ref_v,uq_ref_v,torque_nm,temperature_c,current_ripple_a,"
            "voltage_limited_share,controller_saturated_share");
  auto r = ReadRecordingSet(dir_.string());
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_EQ(r->steady_state.size(), 2u);
  const auto& a = r->steady_state[0];
  const auto& b = r->steady_state[1];
  EXPECT_EQ(a.current_ripple_a, 0.125);
  EXPECT_EQ(a.voltage_limited_share, 0.25);
  EXPECT_EQ(a.controller_saturated_share, 1.0);
  EXPECT_DOUBLE_EQ(*a.torque_nm, 8.5);   // the standard columns unchanged
  EXPECT_EQ(b.current_ripple_a, 3.5);
  EXPECT_FALSE(b.voltage_limited_share.has_value());
  EXPECT_FALSE(b.controller_saturated_share.has_value());
  // The standalone reader reads the same.
  auto rows = ReadSteadyStateCsv((dir_ / "steady_state.csv").string());
  ASSERT_TRUE(rows.ok()) << rows.status();
  EXPECT_EQ((*rows)[0].voltage_limited_share, 0.25);
}

// Any of the extension columns, in any order, each at most once.
TEST_F(RecordingSetTest, SteadyStateExtensionSubsetInAnyOrder) {
  Write("steady_state.csv",
        "id_a,iq_a,speed_rpm,ud_ref_v,uq_ref_v,torque_nm,temperature_c,controller_saturated_share,current_ripple_a\n"
        "-20,60,1000,-10.5,20.25,8.5,25,0.5,0.25\n"
        "0,40,2000,-12.5,22.25,,,,\n");
  auto r = ReadRecordingSet(dir_.string());
  ASSERT_TRUE(r.ok()) << r.status();
  EXPECT_EQ(r->steady_state[0].controller_saturated_share, 0.5);
  EXPECT_EQ(r->steady_state[0].current_ripple_a, 0.25);
  EXPECT_FALSE(r->steady_state[0].voltage_limited_share.has_value());
  EXPECT_FALSE(r->steady_state[1].current_ripple_a.has_value());
}

TEST_F(RecordingSetTest, SteadyStateExtensionBadValues) {
  const std::string header =
      "id_a,iq_a,speed_rpm,ud_ref_v,uq_ref_v,torque_nm,temperature_c,current_ripple_a,voltage_limited_share,"
      "controller_saturated_share\n";
  const std::string good = "-20,60,1000,-10.5,20.25,8.5,25,0.1,0,0\n";
  struct Case {
    std::string row, field, what;
  };
  const Case cases[] = {
      {"0,40,2000,-12.5,22.25,,,0.1,1.5,0\n", "voltage_limited_share", "0..1"},
      {"0,40,2000,-12.5,22.25,,,0.1,0,-0.01\n", "controller_saturated_share", "0..1"},
      {"0,40,2000,-12.5,22.25,,,-0.2,0,0\n", "current_ripple_a", "negative"},
      {"0,40,2000,-12.5,22.25,,,0.1,half,0\n", "voltage_limited_share", "expected a number"},
      {"0,40,2000,-12.5,22.25,,,0.1,0\n", "controller_saturated_share", "missing cell"},
      {"0,40,2000,-12.5,22.25,,,0.1,0,0,7\n", "controller_saturated_share", "too many cells"},
  };
  for (const auto& c : cases) {
    Write("steady_state.csv", header + good + c.row);
    ExpectError(absl::StatusCode::kInvalidArgument, {"steady_state.csv:3", "field '" + c.field + "'", c.what});
  }
  Write("steady_state.csv", "id_a,iq_a,speed_rpm,ud_ref_v,uq_ref_v,torque_nm,temperature_c,ripple_a\n" + good);
  ExpectError(absl::StatusCode::kInvalidArgument,
              {"steady_state.csv:1", "field 'ripple_a'", "unknown column", "current_ripple_a"});
  Write("steady_state.csv",
        "id_a,iq_a,speed_rpm,ud_ref_v,uq_ref_v,torque_nm,temperature_c,current_ripple_a,current_ripple_a\n"
        "-20,60,1000,-10.5,20.25,8.5,25,0.1,0.1\n");
  ExpectError(absl::StatusCode::kInvalidArgument, {"steady_state.csv:1", "field 'current_ripple_a'", "repeated"});
  // Before the standard columns is not after them.
  Write("steady_state.csv",
        "current_ripple_a,id_a,iq_a,speed_rpm,ud_ref_v,uq_ref_v,torque_nm,temperature_c\n"
        "0.1,-20,60,1000,-10.5,20.25,8.5,25\n");
  ExpectError(absl::StatusCode::kInvalidArgument, {"steady_state.csv:1", "field 'id_a'"});
}

// A non-positive inductance is well-formed data: read as it is (the fit
// excludes it and says why); text in the field is still an error.
TEST_F(RecordingSetTest, HfResultsNegativeInductanceIsDataTextIsNot) {
  ReplaceLine("hf_results.csv", 2, "-20,40,0,-1.8e-4,3.5e-4,,");
  auto r = ReadRecordingSet(dir_.string());
  ASSERT_TRUE(r.ok()) << r.status();
  ASSERT_FALSE(r->hf_results.empty());
  EXPECT_EQ(r->hf_results[0].ld_h, -1.8e-4);
  ReplaceLine("hf_results.csv", 2, "-20,40,0,abc,3.5e-4,,");
  ExpectError(absl::StatusCode::kInvalidArgument, {"hf_results.csv:2", "ld_h"});
}

TEST(ExampleSets, ReadAllThree) {
  const fs::path root = fluxcal::testing::SharedExamplesDir();
  if (auto why = fluxcal::testing::MissingSharedExamples({"clean", "dead_time", "cross_saturation"},
                                                "RecordingSetTest.* (a full set written here and read back)");
      !why.empty()) {
    GTEST_SKIP() << why;
  }
  for (const char* name : {"clean", "dead_time", "cross_saturation"}) {
    auto r = ReadRecordingSet((root / name).string());
    ASSERT_TRUE(r.ok()) << name << ": " << r.status();
    EXPECT_EQ(r->manifest.points.size(), 42u) << name;
    for (const auto& w : r->waveforms) EXPECT_EQ(w.size(), 1000u) << name;
    EXPECT_GT(r->steady_state.size(), 0u) << name;
  }
}

TEST(Serial, Rules) {
  EXPECT_TRUE(IsValidSerial("IPM-2026-000123"));
  EXPECT_TRUE(IsValidSerial("a.b_c-D9"));
  EXPECT_FALSE(IsValidSerial(""));
  EXPECT_FALSE(IsValidSerial(std::string(65, 'a')));
  EXPECT_TRUE(IsValidSerial(std::string(64, 'a')));
  EXPECT_FALSE(IsValidSerial("a b"));
  EXPECT_FALSE(IsValidSerial("a/b"));
}


// Every file of the fixture set, by relative name, as a network client sends it.
RecordingFiles FilesOf(const fs::path& dir) {
  RecordingFiles files;
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    std::ifstream f(e.path(), std::ios::binary);
    std::stringstream ss;
    ss << f.rdbuf();
    files[fs::relative(e.path(), dir).generic_string()] = ss.str();
  }
  return files;
}

TEST_F(RecordingSetTest, InMemoryReadEqualsDiskRead) {
  auto disk = ReadRecordingSet(dir_.string());
  ASSERT_TRUE(disk.ok()) << disk.status();
  auto mem = ReadRecordingSetFromFiles(FilesOf(dir_), "upload");
  ASSERT_TRUE(mem.ok()) << mem.status();
  ASSERT_EQ(mem->waveforms.size(), disk->waveforms.size());
  for (size_t k = 0; k < disk->waveforms.size(); ++k) {
    EXPECT_EQ(mem->waveforms[k].ia_a, disk->waveforms[k].ia_a);
    EXPECT_EQ(mem->waveforms[k].theta_e_rad, disk->waveforms[k].theta_e_rad);
  }
  EXPECT_EQ(mem->steady_state.size(), disk->steady_state.size());
  EXPECT_EQ(mem->hf_results.size(), disk->hf_results.size());
  EXPECT_EQ(mem->manifest.serial, disk->manifest.serial);
  // Messages name the in-memory file under the display root.
  auto files = FilesOf(dir_);
  files["points/p001.csv"] += "0.1,x,0,0,0,0,0,\n";
  auto bad = ReadRecordingSetFromFiles(files, "upload");
  ASSERT_FALSE(bad.ok());
  EXPECT_NE(bad.status().message().find("upload/points/p001.csv:202: field 'ia_a'"), std::string::npos)
      << bad.status();
  files.erase("points/p001.csv");
  auto missing = ReadRecordingSetFromFiles(files, "");
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), absl::StatusCode::kNotFound);
  EXPECT_NE(missing.status().message().find("manifest.json:"), std::string::npos) << missing.status();
  EXPECT_NE(missing.status().message().find("points[1].file"), std::string::npos) << missing.status();
}

TEST(RecordingFileName, Rules) {
  for (const char* good : {"manifest.json", "points/p000.csv", "a/b/c/d.csv", "x-y_z.1"}) {
    EXPECT_TRUE(ValidateRecordingFileName(good).ok()) << good;
  }
  for (const std::string& bad : std::vector<std::string>{
           "", "/abs", "../x", "a/../b", "a/./b", "a//b", "a/", ".", "..", "a b", "a\nb", "a\\b",
           std::string("a\0b", 3), "a/b/c/d/e", std::string(256, 'a'), "\xc3\xa9.csv", "a:b"}) {
    auto s = ValidateRecordingFileName(bad);
    EXPECT_EQ(s.code(), absl::StatusCode::kInvalidArgument) << Printable(bad);
    for (unsigned char c : std::string(s.message())) EXPECT_GE(c, 0x20) << "control byte in message";
  }
  // Hostile names never reach a lookup.
  RecordingFiles files{{"../manifest.json", "{}"}};
  EXPECT_EQ(ReadRecordingSetFromFiles(files, "").status().code(), absl::StatusCode::kInvalidArgument);
}

TEST(Printable, EscapesWhatJsonAndLogsCannotCarry) {
  EXPECT_EQ(Printable("plain text 1.5"), "plain text 1.5");
  EXPECT_EQ(Printable("\xc3\xa9t\xc3\xa9"), "\xc3\xa9t\xc3\xa9");          // well-formed UTF-8 kept
  EXPECT_EQ(Printable("a\nb"), "a\\x0ab");
  EXPECT_EQ(Printable("\xff\xfe"), "\\xff\\xfe");
  EXPECT_EQ(Printable("\xc0\xaf"), "\\xc0\\xaf");                        // overlong '/'
  EXPECT_EQ(Printable("\xed\xa0\x80"), "\\xed\\xa0\\x80");                // surrogate
  EXPECT_EQ(Printable("\xe2\x82"), "\\xe2\\x82");                         // truncated
}

TEST_F(RecordingSetTest, OverflowingNumbersAndBadBytesAreErrorsNotCrashes) {
  // 1e999 and a 400-digit integer overflow a double inside the JSON parser.
  Replace("manifest.json", "\"udc_v\": 50.0", "\"udc_v\": 1e999");
  ExpectError(absl::StatusCode::kInvalidArgument, {"manifest.json:1: field '(json)'"});
  Replace("manifest.json", "1e999", std::string(400, '9'));
  ExpectError(absl::StatusCode::kInvalidArgument, {"manifest.json:1: field '(json)'"});
  Replace("manifest.json", std::string(400, '9'), "50.0");
  // Invalid UTF-8 in a CSV header and a cell is echoed escaped.
  ReplaceLine("points/p000.csv", 1, "t_s,ia_a\xff,ib_a,ic_a,theta_e_rad,ualpha_ref_v,ubeta_ref_v,udc_v");
  auto r = ReadRecordingSet(dir_.string());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("ia_a\\xff"), std::string::npos) << r.status();
  ReplaceLine("points/p000.csv", 1, "t_s,ia_a,ib_a,ic_a,theta_e_rad,ualpha_ref_v,ubeta_ref_v,udc_v");
  ReplaceLine("points/p000.csv", 3, "0.0001,\xfe\x01,0,0,0,0,0,");
  r = ReadRecordingSet(dir_.string());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("got '\\xfe\\x01'"), std::string::npos) << r.status();
  // Strings in the manifest: an illegal serial with a newline is escaped.
  Replace("manifest.json", "\"IPM-TEST-001\"", "\"IPM\\nX\\u0000\"");
  r = ReadRecordingSet(dir_.string());
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("illegal serial 'IPM\\x0aX\\x00'"), std::string::npos) << r.status();
}

}  // namespace
}  // namespace fluxcal::io
