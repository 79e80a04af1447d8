// The command line's conventions (docs/cli.md): every registered command
// answers --help with its usage and every flag; a bad flag fails before any
// work; `--out -` writes to stdout; `serve` needs --db; --server HOST means
// port 50051; an unreachable server gets a hint.
#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

#include "cli/args.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "tests/e2e/fluxcal_run.h"

namespace {

namespace fs = std::filesystem;

using Result = fluxcal::e2e::RunResult;
using fluxcal::e2e::ReadFile;
// Runs the binary; stdout and stderr captured.
Result Fluxcal(const std::string& args) { return fluxcal::e2e::RunFluxcal(args); }

nlohmann::json Registry() {
  const Result r = Fluxcal("help --json");
  EXPECT_EQ(r.code, 0) << r.err;
  return nlohmann::json::parse(r.out);
}

TEST(CliConventions, EveryCommandAnswersHelpWithEveryFlag) {
  const nlohmann::json reg = Registry();
  ASSERT_GE(reg.size(), 20u);
  for (const auto& cmd : reg) {
    const std::string name = cmd["name"];
    SCOPED_TRACE(name);
    EXPECT_FALSE(cmd["usage"].get<std::string>().empty());
    ASSERT_FALSE(cmd["flags"].empty()) << "every command declares its flags";
    const Result help = Fluxcal(name + " --help");
    EXPECT_EQ(help.code, 0) << help.err;
    EXPECT_EQ(help.out.rfind("usage: fluxcal " + name, 0), 0u) << help.out;
    for (const auto& f : cmd["flags"]) {
      const std::string flag = "--" + f["name"].get<std::string>();
      const auto at = help.out.find("  " + flag);
      ASSERT_NE(at, std::string::npos) << flag << " missing from\n" << help.out;
      EXPECT_FALSE(f["help"].get<std::string>().empty()) << flag;
    }
    if (cmd["server_client"].get<bool>()) {
      EXPECT_NE(help.out.find("--token-file"), std::string::npos);
    }
    // The same text from -h and from `fluxcal help NAME`.
    const Result h = Fluxcal(name + " -h");
    EXPECT_EQ(h.code, 0);
    EXPECT_EQ(h.out, help.out);
    const Result via_help = Fluxcal("help " + name);
    EXPECT_EQ(via_help.code, 0);
    EXPECT_EQ(via_help.out, help.out);
  }
  // The top-level listing and --version still answer.
  const Result top = Fluxcal("--help");
  EXPECT_EQ(top.code, 0);
  EXPECT_NE(top.out.find("fluxcal help COMMAND"), std::string::npos);
  EXPECT_EQ(Fluxcal("--version").code, 0);
  EXPECT_EQ(Fluxcal("help no-such-command").code, 2);
  EXPECT_EQ(Fluxcal("").code, 2);
  // A value that looks like -h is a value, not a request for help.
  const Result value = Fluxcal("query /nonexistent/cal.json --id-a -h --iq-a 1");
  EXPECT_NE(value.code, 0);
  EXPECT_EQ(value.out.find("usage:"), std::string::npos) << value.out;
}

TEST(CliConventions, BadFlagFailsBeforeAnyWork) {
  // A large set that does not exist: reading it would fail with 1 naming the
  // path; the flag must be refused first (2, naming the flag), at once.
  const auto t0 = std::chrono::steady_clock::now();
  const Result fit = Fluxcal("fit /nonexistent/BIGSET --out /nonexistent/cal.json --bogus");
  EXPECT_EQ(fit.code, 2);
  EXPECT_NE(fit.err.find("--bogus"), std::string::npos) << fit.err;
  EXPECT_EQ(fit.err.find("BIGSET"), std::string::npos) << "the set was read: " << fit.err;
  EXPECT_LT(std::chrono::steady_clock::now() - t0, std::chrono::seconds(5));
  // A bad --model value too, before identification.
  const Result model = Fluxcal("fit /nonexistent/BIGSET --out /nonexistent/cal.json --model polyX");
  EXPECT_EQ(model.code, 2);
  EXPECT_NE(model.err.find("--model"), std::string::npos) << model.err;
  EXPECT_EQ(model.err.find("BIGSET"), std::string::npos) << model.err;
  // Every command: an unknown flag is a usage error naming it.
  for (const auto& cmd : Registry()) {
    const std::string name = cmd["name"];
    const Result r = Fluxcal(name + " /nonexistent/INPUT --no-such-flag");
    EXPECT_EQ(r.code, 2) << name << ": " << r.err;
    EXPECT_NE(r.err.find("--no-such-flag"), std::string::npos) << name << ": " << r.err;
  }
}

TEST(CliConventions, OutDashWritesToStdout) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_conv_out_");
  const std::string measured = std::string(FLUXCAL_SOURCE_DIR) + "/data/real/baldor_fluxmap_measured.csv";
  const std::string cal = (dir / "cal.json").string();
  const std::string fit_args = "fit --map " + measured + " --pole-pairs 2 --serial BALDOR-OUT-1 ";
  ASSERT_EQ(Fluxcal(fit_args + "--out " + cal).code, 0);

  // fit: the calibration JSON on stdout, the summary on stderr.
  const Result fit = Fluxcal(fit_args + "--out -");
  ASSERT_EQ(fit.code, 0) << fit.err;
  const auto doc = nlohmann::json::parse(fit.out);
  EXPECT_EQ(doc["serial"], "BALDOR-OUT-1");
  EXPECT_NE(fit.err.find("BALDOR-OUT-1"), std::string::npos);
  EXPECT_FALSE(fs::exists("-"));

  // export: the same bytes as the file.
  const std::string csv = (dir / "mtpa.csv").string();
  ASSERT_EQ(Fluxcal("export " + cal + " --table mtpa --format csv --points 16 --out " + csv).code, 0);
  const Result ex = Fluxcal("export " + cal + " --table mtpa --format csv --points 16 --out -");
  ASSERT_EQ(ex.code, 0) << ex.err;
  // The same bytes but the creation time, which two runs may put a second
  // apart.
  auto without_time = [](std::string text) {
    const size_t at = text.find("# created_utc: ");
    if (at != std::string::npos) text.erase(at, text.find('\n', at) - at);
    return text;
  };
  EXPECT_EQ(without_time(ex.out), without_time(ReadFile(csv)));

  // map export.
  const std::string map = (dir / "map.csv").string();
  ASSERT_EQ(Fluxcal("map export " + cal + " --out " + map).code, 0);
  const Result me = Fluxcal("map export " + cal + " --out -");
  ASSERT_EQ(me.code, 0) << me.err;
  EXPECT_EQ(me.out, ReadFile(map));

  // report: the HTML page.
  const Result rep = Fluxcal("report " + cal + " --out -");
  ASSERT_EQ(rep.code, 0) << rep.err;
  EXPECT_NE(rep.out.find("<html"), std::string::npos);

  // --out - with --json: both want stdout, a usage error naming both.
  for (const std::string& cmd : {fit_args + "--out - --json", "export " + cal + " --out - --json",
                                 "map export " + cal + " --out - --json", "report " + cal + " --out - --json"}) {
    const Result both = Fluxcal(cmd);
    EXPECT_EQ(both.code, 2) << cmd;
    EXPECT_NE(both.err.find("--out -"), std::string::npos) << both.err;
    EXPECT_NE(both.err.find("--json"), std::string::npos) << both.err;
    EXPECT_TRUE(both.out.empty()) << cmd;
  }
  EXPECT_FALSE(fs::exists("-"));
  fs::remove_all(dir);
}

TEST(CliConventions, ServeRefusesWithoutDb) {
  const fs::path dir = fluxcal::e2e::FreshTempDir("fluxcal_conv_serve_");
  const std::string cmd = "cd " + dir.string() + " && " + std::string(FLUXCAL_BINARY) +
                          " serve --listen 127.0.0.1:0 --quiet 2>&1; echo rc=$?";
  FILE* p = popen(cmd.c_str(), "r");
  std::string out;
  std::array<char, 4096> buf;
  size_t k;
  while ((k = fread(buf.data(), 1, buf.size(), p)) > 0) out.append(buf.data(), k);
  pclose(p);
  EXPECT_NE(out.find("rc=2"), std::string::npos) << out;
  EXPECT_NE(out.find("--db"), std::string::npos) << out;
  EXPECT_FALSE(fs::exists(dir / "fluxcal.db"));
  fs::remove_all(dir);
}

TEST(CliConventions, ServerTargetDefaultsToPort50051) {
  using fluxcal::cli::ServerTarget;
  // A host name, an IPv4 address or a bracketed IPv6 one without a port.
  for (const std::string host : {"localhost", "cal.plant.example", "10.0.0.7", "[::1]"}) {
    EXPECT_EQ(ServerTarget(host), host + ":50051");
  }
  // A bare IPv6 address: bracketed before the port.
  for (const std::string host : {"::1", "fe80::1:2"}) EXPECT_EQ(ServerTarget(host), "[" + host + "]:50051");
  // A port or a gRPC scheme given: kept as it is.
  for (const std::string target : {"localhost:7000", "127.0.0.1:443", "[::1]:7000", "unix:/run/fluxcal.sock",
                                   "dns:///cal.plant.example:50051", "ipv4:127.0.0.1:9"}) {
    EXPECT_EQ(ServerTarget(target), target);
  }
}

TEST(CliConventions, RefusedConnectionGetsAHint) {
  // Port 1 on loopback: nothing listens there, the connection is refused.
  const Result r = Fluxcal("list --server 127.0.0.1:1");
  EXPECT_EQ(r.code, 1);
  EXPECT_NE(r.err.find("cannot reach 127.0.0.1:1"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("fluxcal serve"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--ca"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("UNAVAILABLE"), std::string::npos) << r.err;
}

}  // namespace
