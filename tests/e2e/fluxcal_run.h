// Runs the `fluxcal` binary of this build with stdout and stderr captured
// (for end-to-end tests that check what a command says on stderr), and the
// small text helpers those tests share.
#ifndef FLUXCAL_TESTS_E2E_FLUXCAL_RUN_H_
#define FLUXCAL_TESTS_E2E_FLUXCAL_RUN_H_

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>

namespace fluxcal::e2e {

// The bytes of the file at path ("" when it cannot be read).
inline std::string ReadFile(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

inline bool Has(const std::string& text, const std::string& what) { return text.find(what) != std::string::npos; }

// An empty directory <tmp>/<prefix><pid> (one left by an earlier run removed).
inline std::filesystem::path FreshTempDir(const std::string& prefix) {
  const std::filesystem::path dir = std::filesystem::temp_directory_path() / (prefix + std::to_string(::getpid()));
  std::filesystem::remove_all(dir);
  std::filesystem::create_directories(dir);
  return dir;
}

struct RunResult {
  int code = 0;
  std::string out, err;
};

inline RunResult RunFluxcal(const std::string& args) {
  static int n = 0;
  const std::filesystem::path err = std::filesystem::temp_directory_path() /
                                    ("fluxcal_run_err_" + std::to_string(::getpid()) + "_" + std::to_string(n++));
  const std::string cmd = std::string(FLUXCAL_BINARY) + " " + args + " 2>" + err.string();
  RunResult r;
  FILE* p = popen(cmd.c_str(), "r");
  std::array<char, 4096> buf;
  size_t k;
  while ((k = fread(buf.data(), 1, buf.size(), p)) > 0) r.out.append(buf.data(), k);
  const int st = pclose(p);
  r.code = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  r.err = ReadFile(err);
  std::filesystem::remove(err);
  return r;
}

}  // namespace fluxcal::e2e

#endif  // FLUXCAL_TESTS_E2E_FLUXCAL_RUN_H_
