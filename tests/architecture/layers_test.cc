// The layer rules of docs/architecture.md, checked against the includes
// (issue 26). The application layer's rule (item 1):
// cli/ and server/ only parse, call pipeline/, format and transport. Every
// `#include "X/..."` (or <X/...>) in their sources names X among pipeline,
// io, their own folders and the proto-generated headers (fluxcal/v1/...);
// a folder of this repository outside that list (fitting, tables, storage,
// ...) fails here. Third-party headers (absl/, grpc/, nlohmann/, google/)
// are no folder of the repository and pass. The CMake targets name
// fluxcal_pipeline and fluxcal_io only (cli/CMakeLists.txt,
// server/CMakeLists.txt); the libraries are static and share one include
// root, so this test is what refuses a lower library's header there.
// Below them, every library includes only the folders the graph puts
// under it (kLayers), and no library includes another's internal headers.
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

// What each folder may include of the repository's folders besides its own
// (docs/architecture.md's graph; "fluxcal" is the proto-generated
// fluxcal/v1/... path): the one-way stack, checked against the sources.
const std::vector<std::pair<std::string, std::set<std::string>>> kLayers = {
    {"physics", {}},
    {"plot", {}},
    {"io", {}},
    {"identification", {"io", "physics"}},
    {"simulation", {"io", "physics"}},
    {"fitting", {"identification", "io", "physics", "plot", "simulation"}},
    {"tables", {"fitting", "io", "physics", "plot", "simulation"}},
    {"diagnosis", {"fitting", "identification", "io", "physics", "plot", "simulation"}},
    {"report", {"fitting", "physics", "plot", "tables"}},
    {"storage", {"io"}},
    {"pipeline", {"diagnosis", "fitting", "identification", "io", "physics", "plot", "report", "simulation",
                  "storage", "tables", "fluxcal", "proto"}},
    {"server", {"pipeline", "io", "fluxcal", "proto"}},
    {"cli", {"pipeline", "io", "server", "fluxcal", "proto"}},
};

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

// An include line naming a repository path: its first folder, the rest.
constexpr char kIncludePattern[] = R"(^\s*#\s*include\s*["<]([A-Za-z0-9_.-]+)/([^">]+)[">])";

// Calls visit(file relative to the source root, line number, first folder,
// rest of the path) for every `#include "X/..."` (or <X/...>) in the .cc
// and .h files below folder.
template <class Visit>
void ForEachInclude(const std::string& folder, Visit visit) {
  const std::regex include_re(kIncludePattern);
  for (const auto& e : fs::recursive_directory_iterator(fs::path(FLUXCAL_SOURCE_DIR) / folder)) {
    const std::string ext = e.path().extension().string();
    if (!e.is_regular_file() || (ext != ".cc" && ext != ".h")) continue;
    std::ifstream in(e.path());
    std::string line;
    int n = 0;
    while (std::getline(in, line)) {
      ++n;
      std::smatch m;
      if (std::regex_search(line, m, include_re)) {
        visit(fs::relative(e.path(), FLUXCAL_SOURCE_DIR).string(), n, m[1].str(), m[2].str());
      }
    }
  }
}

std::vector<Violation> Violations(const std::string& folder, const std::set<std::string>& allowed = kAllowed) {
  const std::set<std::string> repo = RepositoryFolders();
  std::vector<Violation> out;
  ForEachInclude(folder, [&](const std::string& file, int n, const std::string& top, const std::string& rest) {
    if (repo.count(top) != 0 && top != folder && allowed.count(top) == 0) out.push_back({file, n, top + "/" + rest});
  });
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

// Every library includes only the folders below it in the graph.
TEST(Layers, EveryFolderIncludesOnlyTheLayersBelowIt) {
  const auto repo = RepositoryFolders();
  for (const auto& [folder, allowed] : kLayers) {
    if (repo.count(folder) == 0) continue;
    const auto v = Violations(folder, allowed);
    EXPECT_TRUE(v.empty()) << folder << "/ includes a folder docs/architecture.md does not put below it:\n"
                           << Describe(v);
  }
}

// A header whose declarations live in a namespace `internal` or `detail`
// (fitting's residuals and solver steps, tables/internal_*.h,
// diagnosis/internal.h) is its library's own: no other folder includes it
// (its tests may).
bool DeclaresInternalNamespace(const fs::path& header) {
  std::ifstream in(header);
  const std::regex ns_re(R"(^\s*namespace\s+[A-Za-z0-9_:]*::(internal|detail)\b)");
  std::string line;
  while (std::getline(in, line)) {
    if (std::regex_search(line, ns_re)) return true;
  }
  return false;
}

TEST(Layers, InternalHeadersStayInTheirLibrary) {
  std::vector<Violation> v;
  for (const auto& [folder, allowed] : kLayers) {
    if (!fs::is_directory(fs::path(FLUXCAL_SOURCE_DIR) / folder)) continue;
    ForEachInclude(folder, [&](const std::string& file, int n, const std::string& top, const std::string& rest) {
      if (top == folder) return;
      const fs::path header = fs::path(FLUXCAL_SOURCE_DIR) / top / rest;
      if (fs::is_regular_file(header) && DeclaresInternalNamespace(header)) v.push_back({file, n, top + "/" + rest});
    });
  }
  EXPECT_TRUE(v.empty()) << "a library's internal header included from another folder:\n" << Describe(v);
}

TEST(Layers, FindsTheInternalHeaders) {
  EXPECT_TRUE(DeclaresInternalNamespace(fs::path(FLUXCAL_SOURCE_DIR) / "diagnosis" / "internal.h"));
  EXPECT_FALSE(DeclaresInternalNamespace(fs::path(FLUXCAL_SOURCE_DIR) / "pipeline" / "pipeline.h"));
}

// The check itself: a line naming a library below pipeline/ is caught.
TEST(Layers, CatchesAnInclude) {
  const fs::path dir = fs::path(FLUXCAL_SOURCE_DIR) / "fitting";
  ASSERT_TRUE(fs::is_directory(dir));
  const std::regex include_re(kIncludePattern);
  std::smatch m;
  const std::string line = "#include \"fitting/fit.h\"";
  ASSERT_TRUE(std::regex_search(line, m, include_re));
  EXPECT_EQ(m[1].str(), "fitting");
  EXPECT_EQ(kAllowed.count(m[1].str()), 0u);
}

}  // namespace
