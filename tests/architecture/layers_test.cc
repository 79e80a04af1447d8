// The application layer's rule (docs/architecture.md, issue 26 item 1):
// cli/ and server/ only parse, call pipeline/, format and transport. Every
// `#include "X/..."` (or <X/...>) in their sources names X among pipeline,
// io, their own folders and the proto-generated headers (fluxcal/v1/...);
// a folder of this repository outside that list (fitting, tables, storage,
// ...) fails here. Third-party headers (absl/, grpc/, nlohmann/, google/)
// are no folder of the repository and pass. The CMake targets link
// fluxcal_pipeline and fluxcal_io only (cli/CMakeLists.txt,
// server/CMakeLists.txt), so the build refuses a call this test misses.
#include <filesystem>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace {

namespace fs = std::filesystem;

const std::set<std::string> kAllowed = {"pipeline", "io", "cli", "server", "proto", "fluxcal"};

// The folders at the repository's root: what an include's first component
// must be to name one of fluxcal's libraries.
std::set<std::string> RepositoryFolders() {
  std::set<std::string> out;
  for (const auto& e : fs::directory_iterator(FLUXCAL_SOURCE_DIR)) {
    if (e.is_directory() && e.path().filename().string()[0] != '.') out.insert(e.path().filename().string());
  }
  return out;
}

struct Violation {
  std::string file;
  int line;
  std::string include;
};

std::vector<Violation> Violations(const std::string& folder) {
  const std::set<std::string> repo = RepositoryFolders();
  const std::regex include_re(R"(^\s*#\s*include\s*["<]([A-Za-z0-9_.-]+)/([^">]+)[">])");
  std::vector<Violation> out;
  for (const auto& e : fs::recursive_directory_iterator(fs::path(FLUXCAL_SOURCE_DIR) / folder)) {
    const std::string ext = e.path().extension().string();
    if (!e.is_regular_file() || (ext != ".cc" && ext != ".h")) continue;
    std::ifstream in(e.path());
    std::string line;
    int n = 0;
    while (std::getline(in, line)) {
      ++n;
      std::smatch m;
      if (!std::regex_search(line, m, include_re)) continue;
      const std::string top = m[1];
      if (repo.count(top) != 0 && kAllowed.count(top) == 0) {
        out.push_back({fs::relative(e.path(), FLUXCAL_SOURCE_DIR).string(), n, top + "/" + m[2].str()});
      }
    }
  }
  return out;
}

std::string Describe(const std::vector<Violation>& v) {
  std::ostringstream os;
  for (const auto& x : v) os << "  " << x.file << ":" << x.line << ": includes " << x.include << "\n";
  return os.str();
}

TEST(Layers, RepositoryFoldersAreFound) {
  // The scan means something only if the libraries it guards are seen.
  const auto repo = RepositoryFolders();
  for (const char* lib : {"fitting", "tables", "storage", "identification", "diagnosis", "simulation", "pipeline"}) {
    EXPECT_EQ(repo.count(lib), 1u) << lib;
  }
}

TEST(Layers, CliIncludesOnlyPipelineAndIo) {
  const auto v = Violations("cli");
  EXPECT_TRUE(v.empty()) << "cli/ includes a library below pipeline/ (call a pipeline/ use case instead):\n"
                         << Describe(v);
}

TEST(Layers, ServerIncludesOnlyPipelineAndIo) {
  const auto v = Violations("server");
  EXPECT_TRUE(v.empty()) << "server/ includes a library below pipeline/ (call a pipeline/ use case instead):\n"
                         << Describe(v);
}

// The check itself: a line naming a library below pipeline/ is caught.
TEST(Layers, CatchesAnInclude) {
  const fs::path dir = fs::path(FLUXCAL_SOURCE_DIR) / "fitting";
  ASSERT_TRUE(fs::is_directory(dir));
  const std::regex include_re(R"(^\s*#\s*include\s*["<]([A-Za-z0-9_.-]+)/([^">]+)[">])");
  std::smatch m;
  const std::string line = "#include \"fitting/fit.h\"";
  ASSERT_TRUE(std::regex_search(line, m, include_re));
  EXPECT_EQ(m[1].str(), "fitting");
  EXPECT_EQ(kAllowed.count(m[1].str()), 0u);
}

}  // namespace
