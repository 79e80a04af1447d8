// A mutational fuzz run inside ctest (any compiler; libFuzzer runs the same
// entry point under scripts/fuzz.sh): the kept crash corpus as regression
// tests, then deterministic mutations of every file of a valid set and of
// the stored-archive codec. FLUXCAL_FUZZ_RUNS sets the number of mutations
// per target (default 25000; 4 file targets + the archive).
//
// On a crash the input being run is written to fuzz-crash.bin in the
// working directory (signal handler), ready for tests/fuzz/corpus/.
#include <fcntl.h>
#include <unistd.h>

#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "pipeline/recording_archive.h"
#include "tests/fuzz/recording_fuzz.h"

namespace fluxcal::fuzz {
namespace {

namespace fs = std::filesystem;

std::string g_current;   // the input under test, for the crash handler

void OnCrash(int sig) {
  const int fd = ::open("fuzz-crash.bin", O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd >= 0) {
    [[maybe_unused]] auto n = ::write(fd, g_current.data(), g_current.size());
    ::close(fd);
  }
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

size_t Runs() {
  const char* e = std::getenv("FLUXCAL_FUZZ_RUNS");
  return e ? std::strtoul(e, nullptr, 10) : 25000;
}

// Tokens that broke or could break readers: overflowing numbers, non-finite
// spellings, separators, invalid UTF-8, JSON structure.
const std::vector<std::string>& Dictionary() {
  static const std::vector<std::string> d = {
      "1e999", "-1e999", std::string(400, '9'), "nan", "inf", "-0", "0x1p3", "1e-400", ",", ",,", "\n", "\r\n",
      "\"", "{", "}", "[", "]", ":", "null", "true", "\xff", "\xc3", "\xed\xa0\x80", std::string(1, '\0'), "\\u0000",
      "\\ud800", "points/../x", "/etc/passwd", "t_s", "ia_a", "udc_v", "ld_h", "\"points\": []", "-1", "1e308",
      "4.9e-324", "2147483648", "-9223372036854775809", "  ", "\t"};
  return d;
}

std::string Mutate(std::string s, std::mt19937_64& rng) {
  const int n = 1 + static_cast<int>(rng() % 4);
  for (int k = 0; k < n; ++k) {
    const size_t pos = s.empty() ? 0 : rng() % (s.size() + 1);
    switch (rng() % 7) {
      case 0:   // flip a bit
        if (!s.empty()) s[pos % s.size()] ^= static_cast<char>(1u << (rng() % 8));
        break;
      case 1:   // random byte
        s.insert(pos, 1, static_cast<char>(rng() & 0xff));
        break;
      case 2: {  // delete a range
        if (s.empty()) break;
        const size_t len = 1 + rng() % 64;
        s.erase(pos % s.size(), len);
        break;
      }
      case 3: {  // duplicate a range
        if (s.empty()) break;
        const size_t a = pos % s.size(), len = std::min<size_t>(1 + rng() % 256, s.size() - a);
        s.insert(a, s.substr(a, len));
        break;
      }
      case 4:   // dictionary token
        s.insert(pos, Dictionary()[rng() % Dictionary().size()]);
        break;
      case 5: {  // overwrite with a token
        const auto& t = Dictionary()[rng() % Dictionary().size()];
        if (pos < s.size()) s.replace(pos, std::min(t.size(), s.size() - pos), t);
        break;
      }
      case 6:   // truncate
        s.resize(pos);
        break;
    }
  }
  return s;
}

class FuzzTest : public ::testing::Test {
 protected:
  void SetUp() override {
    std::signal(SIGABRT, OnCrash);
    std::signal(SIGSEGV, OnCrash);
  }
  void TearDown() override {
    std::signal(SIGABRT, SIG_DFL);
    std::signal(SIGSEGV, SIG_DFL);
  }
};

TEST_F(FuzzTest, KeptCorpusStillPasses) {
  const fs::path dir = fs::path(FLUXCAL_SOURCE_DIR) / "tests/fuzz/corpus";
  size_t n = 0;
  for (const auto& e : fs::directory_iterator(dir)) {
    std::ifstream f(e.path(), std::ios::binary);
    g_current.assign(std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>());
    RunOne(reinterpret_cast<const uint8_t*>(g_current.data()), g_current.size());
    ++n;
  }
  EXPECT_GT(n, 0u) << "the corpus in " << dir << " is empty";
}

TEST_F(FuzzTest, TheBaseSetIsAccepted) {
  for (size_t t = 0; t < std::size(kTargets); ++t) {
    g_current = MakeInput(t, BaseSet().at(kTargets[t]));
    EXPECT_EQ(RunOne(reinterpret_cast<const uint8_t*>(g_current.data()), g_current.size()), 1) << kTargets[t];
  }
}

TEST_F(FuzzTest, MutatedFilesNeverCrashAndAlwaysNameFileAndField) {
  std::mt19937_64 rng(20261123);
  size_t accepted = 0, rejected = 0;
  for (size_t t = 0; t < std::size(kTargets); ++t) {
    std::string current = BaseSet().at(kTargets[t]);
    for (size_t i = 0; i < Runs(); ++i) {
      // Mostly mutate the valid file; sometimes keep walking from the last
      // mutant so that damage accumulates.
      const std::string m = Mutate(rng() % 4 ? BaseSet().at(kTargets[t]) : current, rng);
      g_current = MakeInput(t, m);
      if (RunOne(reinterpret_cast<const uint8_t*>(g_current.data()), g_current.size())) {
        ++accepted;
      } else {
        ++rejected;
      }
      current = m;
    }
  }
  // Both outcomes are exercised: mutations that keep the file valid (e.g. in
  // a number's last digit) and ones that break it.
  EXPECT_GT(accepted, Runs() / 50);
  EXPECT_GT(rejected, Runs());
}

TEST_F(FuzzTest, MutatedArchivesNeverCrash) {
  std::mt19937_64 rng(7);
  const std::string good = pipeline::EncodeRecordingArchive(BaseSet());
  std::string legacy;
  for (const auto& [name, data] : BaseSet()) legacy += name + "\n" + std::to_string(data.size()) + "\n" + data;
  size_t ok = 0;
  for (size_t i = 0; i < Runs(); ++i) {
    g_current = Mutate(i % 2 ? good : legacy, rng);
    auto files = pipeline::DecodeRecordingArchive(g_current);
    if (!files.ok()) continue;
    ++ok;
    for (const auto& [name, data] : *files) ASSERT_TRUE(io::ValidateRecordingFileName(name).ok()) << name;
    (void)io::ReadRecordingSetFromFiles(*files, "");
  }
  EXPECT_GT(ok, 0u);
}

}  // namespace
}  // namespace fluxcal::fuzz
