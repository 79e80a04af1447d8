// A newcomer's first hour (issue 25, item 5), through the `fluxcal` binary:
//  - one overwrite rule: every command that writes a file refuses one that
//    exists unless --force, before any work, naming the flag and the path
//    (before: fit, export, report overwrote silently, map export refused);
//  - progress off a terminal is one line per update (before: "fit:
//    identifying point 1/42fit: identifying point 2/42..." on one line);
//  - `fluxcal --version` names the commit and the build type (before: only
//    the release);
//  - exit codes as docs/cli.md says: a refusal naming a flag is 2, a table
//    refused for what it would contain (the MTPV curve outside the current
//    limit) is 1.
// Data: a twin set simulated here and the public Baldor EOL file in
// data/real (in the repository).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <regex>
#include <string>

#include "absl/status/status.h"
#include "cli/args.h"
#include "cli/support_progress.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "tests/e2e/fluxcal_run.h"

namespace fluxcal::e2e {
namespace {

namespace fs = std::filesystem;


// The stdout of a shell command.
std::string Shell(const std::string& cmd) {
  std::string out;
  FILE* p = popen(cmd.c_str(), "r");
  if (p == nullptr) return out;
  char buf[4096];
  size_t k;
  while ((k = fread(buf, 1, sizeof buf, p)) > 0) out.append(buf, k);
  pclose(p);
  while (!out.empty() && (out.back() == '\n' || out.back() == '\r')) out.pop_back();
  return out;
}

std::string Refusal(const std::string& flag, const std::string& path) {
  return "flag --" + flag + ": '" + path + "' exists";
}

// The command was refused (exit 1) with `refusal` on stderr.
::testing::AssertionResult RefusedWith(const RunResult& r, const std::string& refusal) {
  const bool exit_1 = r.code == 1, said = Has(r.err, refusal);
  if (exit_1 && said) return ::testing::AssertionSuccess();
  auto failure = ::testing::AssertionFailure();
  if (!exit_1) failure << "exit " << r.code << ", not 1; ";
  if (!said) failure << "no '" << refusal << "' on stderr; ";
  return failure << "stderr: " << r.err;
}

class Newcomer : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new fs::path(fluxcal::e2e::FreshTempDir("fluxcal_newcomer_"));
    ASSERT_EQ(RunFluxcal("simulate --out " + Path("set") + " --seed 3 --serial IPM-NEW-1").code, 0);
    ASSERT_EQ(RunFluxcal("fit " + Path("set") + " --model analytic --out " + Path("cal.json")).code, 0);
  }
  static void TearDownTestSuite() {
    fs::remove_all(*dir_);
    delete dir_;
  }
  static std::string Path(const std::string& name) { return (*dir_ / name).string(); }
  // A file that must survive a refused command as it was.
  static std::string Existing(const std::string& name) {
    const std::string p = Path(name);
    std::ofstream(p) << "kept\n";
    return p;
  }
  // `command --<flag> FILE`, FILE the existing file `name`: refused, naming
  // the flag and the file, and the file kept as it was. Returns FILE.
  static std::string ExpectKept(const std::string& command, const std::string& flag, const std::string& name) {
    const std::string file = Existing(name);
    const RunResult r = RunFluxcal(command + " --" + flag + " " + file);
    EXPECT_TRUE(RefusedWith(r, Refusal(flag, file)));
    EXPECT_EQ(ReadFile(file), "kept\n");
    return file;
  }
  static fs::path* dir_;
};
fs::path* Newcomer::dir_ = nullptr;

// ---- one overwrite rule ----------------------------------------------------

TEST_F(Newcomer, FitRefusesAnExistingOutputBeforeAnyWork) {
  const std::string out = Existing("fit_out.json");
  const RunResult r = RunFluxcal("fit " + Path("set") + " --model analytic --out " + out);
  EXPECT_TRUE(RefusedWith(r, Refusal("out", out) + "; not overwritten (give --force to replace it)"));
  EXPECT_FALSE(Has(r.err, "identifying point")) << "refused before identifying: " << r.err;
  EXPECT_EQ(ReadFile(out), "kept\n");
  const std::string svg = Existing("fit.svg");
  const RunResult s = RunFluxcal("fit " + Path("set") + " --model analytic --out " + Path("fit_new.json") + " --svg " + svg);
  EXPECT_TRUE(RefusedWith(s, Refusal("svg", svg)));
  EXPECT_FALSE(fs::exists(Path("fit_new.json"))) << "nothing written on a refusal";
  const RunResult f = RunFluxcal("fit " + Path("set") + " --model analytic --force --out " + out + " --svg " + svg);
  ASSERT_EQ(f.code, 0) << f.err;
  EXPECT_EQ(nlohmann::json::parse(ReadFile(out))["format"], "fluxcal.calibration.v1");
  EXPECT_TRUE(Has(ReadFile(svg), "<svg"));
}

TEST_F(Newcomer, ExportRefusesAnExistingTableOrSignature) {
  const std::string cal = Path("cal.json");
  ExpectKept("export " + cal + " --table mtpa", "out", "mtpa.csv");
  // A signature beside the file name counts: it would vouch for other bytes.
  const std::string fresh = Path("fresh.csv");
  const std::string sig = Existing("fresh.csv.sig");
  const RunResult g = RunFluxcal("export " + cal + " --table mtpa --out " + fresh);
  EXPECT_TRUE(RefusedWith(g, Refusal("out", sig)));
  EXPECT_FALSE(fs::exists(fresh));
  // --force: the table replaced, the old signature of another table gone.
  const RunResult f = RunFluxcal("export " + cal + " --table mtpa --force --out " + fresh);
  ASSERT_EQ(f.code, 0) << f.err;
  EXPECT_TRUE(fs::exists(fresh));
  EXPECT_FALSE(fs::exists(sig)) << "a stale OUT.sig stays beside a table it did not sign";
  // Stdout is never "existing output".
  const RunResult d = RunFluxcal("export " + cal + " --table mtpa --out -");
  EXPECT_EQ(d.code, 0) << d.err;
}

TEST_F(Newcomer, ReportMapExportSimulateDiagnoseAndKeygenShareTheRule) {
  const std::string cal = Path("cal.json");
  {
    const std::string page = ExpectKept("report " + cal, "out", "page.html");
    EXPECT_EQ(RunFluxcal("report " + cal + " --force --out " + page).code, 0);
    EXPECT_TRUE(Has(ReadFile(page), "<html"));
  }
  {
    const std::string map = Existing("map.csv");
    const RunResult r = RunFluxcal("map export " + cal + " --out " + map);
    EXPECT_TRUE(RefusedWith(r, Refusal("out", map)));
    EXPECT_EQ(RunFluxcal("map export " + cal + " --force --out " + map).code, 0);
  }
  {
    // A set directory with files in it, or its truth file, is refused; an
    // empty directory is not existing output.
    const RunResult r = RunFluxcal("simulate --seed 4 --out " + Path("set"));
    EXPECT_TRUE(RefusedWith(r, Refusal("out", Path("set")) + " and is not empty"));
    const std::string truth = Existing("lonely.truth.json");
    const RunResult t = RunFluxcal("simulate --seed 4 --out " + Path("lonely"));
    EXPECT_TRUE(RefusedWith(t, Refusal("out", truth)));
    EXPECT_FALSE(fs::exists(Path("lonely")));
    fs::create_directories(Path("empty"));
    EXPECT_EQ(RunFluxcal("simulate --seed 4 --out " + Path("empty")).code, 0);
    EXPECT_EQ(RunFluxcal("simulate --seed 5 --force --out " + Path("empty")).code, 0);
  }
  {
    const std::string out = Existing("diag_cal.json");
    const RunResult r = RunFluxcal("diagnose " + Path("set") + " --calibration-out " + out);
    EXPECT_TRUE(RefusedWith(r, Refusal("calibration-out", out)));
    EXPECT_FALSE(Has(r.err, "steady-state rows")) << "refused before reading the set: " << r.err;
    fs::create_directories(Path("plots"));
    const std::string svg = Existing("plots/residual_after.svg");
    const RunResult p = RunFluxcal("diagnose " + Path("set") + " --plots " + Path("plots"));
    EXPECT_TRUE(RefusedWith(p, Refusal("plots", svg)));
  }
  {
    const std::string pub = Existing("k.pub");
    const RunResult r = RunFluxcal("admin keygen --out " + Path("k"));
    EXPECT_TRUE(RefusedWith(r, Refusal("out", pub)));
    EXPECT_FALSE(fs::exists(Path("k.key"))) << "no half key pair";
    EXPECT_EQ(RunFluxcal("admin keygen --force --out " + Path("k")).code, 0);
    EXPECT_TRUE(Has(ReadFile(pub), "PUBLIC KEY"));
  }
}

TEST(OverwriteRule, CheckOverwrite) {
  const fs::path dir = fs::temp_directory_path() / ("fluxcal_overwrite_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "empty");
  fs::create_directories(dir / "full");
  std::ofstream(dir / "full" / "x") << "x";
  std::ofstream(dir / "file") << "x";
  auto args = cli::ParseArgs({}, {cli::kForceFlag});
  ASSERT_TRUE(args.ok());
  EXPECT_EQ(cli::CheckOverwrite(*args, {{"out", (dir / "new").string()}, {"out", "-"}, {"out", ""}}), "");
  EXPECT_EQ(cli::CheckOverwrite(*args, {{"out", (dir / "empty").string()}}), "");
  EXPECT_EQ(cli::CheckOverwrite(*args, {{"out", (dir / "file").string()}}),
            "flag --out: '" + (dir / "file").string() + "' exists; not overwritten (give --force to replace it)");
  EXPECT_TRUE(Has(cli::CheckOverwrite(*args, {{"plots", (dir / "full").string()}}), "flag --plots: "));
  EXPECT_TRUE(Has(cli::CheckOverwrite(*args, {{"plots", (dir / "full").string()}}), "exists and is not empty"));
  auto forced = cli::ParseArgs({"--force"}, {cli::kForceFlag});
  ASSERT_TRUE(forced.ok());
  EXPECT_EQ(cli::CheckOverwrite(*forced, {{"out", (dir / "file").string()}, {"out", (dir / "full").string()}}), "");
  const absl::Status w = cli::WriteNewOutput(*args, {"out", (dir / "file").string()}, "new");
  EXPECT_TRUE(absl::IsFailedPrecondition(w)) << w;
  EXPECT_EQ(ReadFile(dir / "file"), "x");
  EXPECT_TRUE(cli::WriteNewOutput(*forced, {"out", (dir / "file").string()}, "new").ok());
  EXPECT_EQ(ReadFile(dir / "file"), "new");
  fs::remove_all(dir);
}

// Every command that writes a file declares --force (the registry is what
// `--help` and the parser use).
TEST(OverwriteRule, EveryWritingCommandTakesForce) {
  const RunResult r = RunFluxcal("help --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto reg = nlohmann::json::parse(r.out);
  for (const char* name : {"fit", "export", "report", "map export", "simulate", "diagnose", "admin keygen", "admin",
                           "eol"}) {
    bool found = false, force = false;
    for (const auto& cmd : reg) {
      if (cmd["name"] != name) continue;
      found = true;
      for (const auto& f : cmd["flags"]) force = force || f["name"] == "force";
    }
    EXPECT_TRUE(found) << name;
    EXPECT_TRUE(force) << "fluxcal " << name << " writes a file and takes no --force";
  }
}

// ---- progress ---------------------------------------------------------------

TEST(Progress, OneLinePerUpdateOffATerminalRewrittenOnOne) {
  for (const bool terminal : {false, true}) {
    std::FILE* f = std::tmpfile();
    ASSERT_NE(f, nullptr);
    const cli::ProgressLine line("fit: identifying point", f, terminal);
    const auto cb = line.Callback();
    for (size_t k = 0; k < 3; ++k) cb(k, 3);
    std::rewind(f);
    std::string text;
    char buf[256];
    size_t n;
    while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
    std::fclose(f);
    EXPECT_EQ(text, terminal ? "\rfit: identifying point 1/3\rfit: identifying point 2/3\rfit: identifying point 3/3\n"
                             : "fit: identifying point 1/3\nfit: identifying point 2/3\nfit: identifying point 3/3\n")
        << (terminal ? "terminal" : "not a terminal");
  }
}

TEST_F(Newcomer, ProgressInALogIsLines) {
  for (const std::string& cmd : {"fit " + Path("set") + " --model analytic --force --out " + Path("p.json"),
                                "identify " + Path("set") + " --csv",
                                "report " + Path("cal.json") + " --set " + Path("set") + " --out " + Path("p.html")}) {
    const RunResult r = RunFluxcal(cmd);   // stderr is a file here, not a terminal
    ASSERT_EQ(r.code, 0) << cmd << ": " << r.err;
    EXPECT_EQ(r.err.find('\r'), std::string::npos) << cmd << ": carriage return in a log:\n" << r.err;
    const std::string label = cmd.rfind("fit", 0) == 0        ? "fit: identifying point "
                              : cmd.rfind("identify", 0) == 0 ? "identify: point "
                                                              : "report: identifying point ";
    EXPECT_TRUE(Has(r.err, label + "1/40\n" + label + "2/40\n")) << cmd << ":\n" << r.err;
    EXPECT_TRUE(Has(r.err, label + "40/40\n")) << cmd << ":\n" << r.err;
  }
}

// ---- --version ---------------------------------------------------------------

TEST(Version, NamesReleaseCommitAndBuildType) {
  const RunResult r = RunFluxcal("--version");
  ASSERT_EQ(r.code, 0) << r.err;
  std::smatch m;
  ASSERT_TRUE(std::regex_match(r.out, m, std::regex(R"(fluxcal (\d+\.\d+\.\d+) \(commit (\S+), (\S+) build\)\n)")))
      << r.out;
  EXPECT_EQ(m[3].str(), FLUXCAL_TEST_BUILD_TYPE);
  std::string commit = m[2].str();
  const std::string src = FLUXCAL_SOURCE_DIR;
  const std::string top = Shell("git -C '" + src + "' rev-parse --show-toplevel 2>/dev/null");
  if (!top.empty() && fs::equivalent(top, src)) {
    // git describe --always --dirty: [TAG-N-g]HASH[-dirty], HASH a prefix of HEAD's.
    if (commit.size() > 6 && commit.substr(commit.size() - 6) == "-dirty") commit.resize(commit.size() - 6);
    if (auto g = commit.rfind("-g"); g != std::string::npos) commit = commit.substr(g + 2);
    const std::string head = Shell("git -C '" + src + "' rev-parse HEAD");
    EXPECT_GE(commit.size(), 7u) << m[2];
    EXPECT_EQ(head.rfind(commit, 0), 0u) << "commit " << m[2] << " vs HEAD " << head;
  } else {
    EXPECT_EQ(commit, "unknown") << "the sources are not a git checkout";
  }
  const RunResult j = RunFluxcal("--version --json");
  ASSERT_EQ(j.code, 0) << j.err;
  const auto doc = nlohmann::json::parse(j.out);
  EXPECT_EQ(doc["version"], m[1].str());
  EXPECT_EQ(doc["commit"], m[2].str());
  EXPECT_EQ(doc["build_type"], FLUXCAL_TEST_BUILD_TYPE);
  EXPECT_EQ(RunFluxcal("--version --bogus").code, 2);
}

// Outside a git checkout (a tarball, a copy without .git) the commit is
// "unknown", never the commit of a repository around it.
TEST(Version, UnknownOutsideAGitCheckout) {
  const fs::path dir = fs::temp_directory_path() / ("fluxcal_buildinfo_" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir / "src");
  const std::string header = (dir / "build_info.h").string();
  const std::string cmd = std::string("'") + FLUXCAL_CMAKE + "' -DSOURCE_DIR='" + (dir / "src").string() +
                          "' -DOUT='" + header + "' -DBUILD_TYPE=Debug -P '" + FLUXCAL_SOURCE_DIR +
                          "/cmake/build_info.cmake'";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << cmd;
  const std::string text = ReadFile(header);
  EXPECT_TRUE(Has(text, "#define FLUXCAL_GIT_DESCRIBE \"unknown\"")) << text;
  EXPECT_TRUE(Has(text, "#define FLUXCAL_BUILD_TYPE \"Debug\"")) << text;
  fs::remove_all(dir);
}

// ---- exit codes ----------------------------------------------------------------

TEST(ExitCodes, ARefusalNamingAFlagIsTwoAnyOtherIsOne) {
  EXPECT_EQ(cli::ExitCodeFor(absl::OkStatus()), 0);
  EXPECT_EQ(cli::ExitCodeFor(absl::InvalidArgumentError("flag --udc-v: the mtpv table ...")), 2);
  EXPECT_EQ(cli::ExitCodeFor(absl::InvalidArgumentError("--points: 64 breakpoints cannot hold ...")), 2);
  EXPECT_EQ(cli::ExitCodeFor(absl::InvalidArgumentError("limits: pole_pairs unknown")), 1);
  EXPECT_EQ(cli::ExitCodeFor(absl::FailedPreconditionError("table mtpv: at every flux ...")), 1);
  EXPECT_EQ(cli::ExitCodeFor(absl::FailedPreconditionError("flag --out: 'x' exists")), 1);
}

// The MTPV refusal of the issue: the Baldor machine's MTPV curve lies
// beyond its measured current limit at every flux. docs/cli.md: 1 (a
// table refused for what it would contain); without a Udc it is a flag to
// give: 2.
TEST_F(Newcomer, MtpvRefusalsExitAsDocumented) {
  const std::string cal = Path("baldor.json");
  ASSERT_EQ(RunFluxcal("fit " + std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_eol --out " + cal).code, 0);
  const RunResult r = RunFluxcal("export " + cal + " --table mtpv --out " + Path("mtpv.csv"));
  EXPECT_EQ(r.code, 1) << r.err;
  EXPECT_TRUE(Has(r.err, "the MTPV point lies beyond the current limit")) << r.err;
  EXPECT_FALSE(fs::exists(Path("mtpv.csv")));
  const std::string no_udc = Path("no_udc.json");
  ASSERT_EQ(RunFluxcal("fit " + std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_eol/hf_results.csv --serial B-1 "
                       "--pole-pairs 2 --psi-pm-wb 0.444 --out " + no_udc).code, 0);
  const RunResult u = RunFluxcal("export " + no_udc + " --table mtpv --out " + Path("mtpv.csv"));
  EXPECT_EQ(u.code, 2) << u.err;
  EXPECT_TRUE(Has(u.err, "flag --udc-v")) << u.err;
}

}  // namespace
}  // namespace fluxcal::e2e
