// The independent example recording sets (clean, dead_time,
// cross_saturation: about 3 MB each, with their truth files) live beside
// the repository in ../shared/examples and are not copied into it. A test
// that uses them skips in a clone on its own, with a message naming the
// files it misses and the in-repo test that keeps its core assertion:
//
//   if (auto why = fluxcal::testing::MissingSharedExamples({"clean"}, "ZohRoundTrip.*"); !why.empty())
//     GTEST_SKIP() << why;
//
// The real machine's data (the measured Baldor map and its EOL file) is in
// the repository (data/real/) and never skips.
#ifndef FLUXCAL_TESTS_SUPPORT_SHARED_EXAMPLES_H_
#define FLUXCAL_TESTS_SUPPORT_SHARED_EXAMPLES_H_

#include <filesystem>
#include <initializer_list>
#include <string>

namespace fluxcal::testing {

inline std::filesystem::path SharedExamplesDir() {
  return std::filesystem::path(FLUXCAL_SHARED_DIR) / "examples";
}

// Empty when every named set and its truth file exist; otherwise a
// message naming the first missing path and `in_repo`, the test that
// holds the same assertion on in-repo data.
inline std::string MissingSharedExamples(std::initializer_list<const char*> sets, const std::string& in_repo) {
  namespace fs = std::filesystem;
  const fs::path root = SharedExamplesDir();
  for (const char* name : sets) {
    for (const fs::path& p : {root / name / "manifest.json", root / (std::string(name) + ".truth.json")}) {
      if (!fs::exists(p)) {
        return "skipped: needs " + p.lexically_normal().string() +
               " (the independent example sets beside the repository, ../shared/examples, not part of a clone); "
               "in-repo equivalent: " + in_repo;
      }
    }
  }
  return "";
}

}  // namespace fluxcal::testing

#endif  // FLUXCAL_TESTS_SUPPORT_SHARED_EXAMPLES_H_
