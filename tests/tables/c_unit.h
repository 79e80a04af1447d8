// The exported C headers as an ECU build would use them: a program over
// them compiled by the system C compiler in strict C99 with warnings as
// errors, run, and its printout handed back. Shared by the header tests so
// that every one builds the same way.
#ifndef FLUXCAL_TESTS_TABLES_C_UNIT_H_
#define FLUXCAL_TESTS_TABLES_C_UNIT_H_

#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include "gtest/gtest.h"
#include "tables/tables.h"

namespace fluxcal::tables {

// Writes `files` (name, contents) and main.c = `prog` to the directory
// `name` under the test's temp dir, compiles with -std=c99 -pedantic -Wall
// -Wextra -Werror and `extra_flags`, runs the program and sets *printed to
// its standard output. A fatal failure (`what`, the build log's path and
// the program) when it does not build or run: callers wrap the call in
// ASSERT_NO_FATAL_FAILURE.
inline void BuildAndRunC99(const std::string& name, const std::vector<std::pair<std::string, std::string>>& files,
                           const std::string& prog, const std::string& extra_flags, const std::string& what,
                           std::string* printed) {
  const std::string dir = ::testing::TempDir() + "/" + name;
  ASSERT_EQ(std::system(("mkdir -p " + dir).c_str()), 0);
  for (const auto& [file, contents] : files) std::ofstream(dir + "/" + file) << contents;
  { std::ofstream(dir + "/main.c") << prog; }
  const std::string cmd = "cd " + dir + " && cc -std=c99 -pedantic -Wall -Wextra -Werror " + extra_flags +
                          " main.c -o main > build.log 2>&1 && ./main > out.txt";
  ASSERT_EQ(std::system(cmd.c_str()), 0) << what << "; see " << dir << "/build.log\n" << prog;
  std::ifstream out(dir + "/out.txt");
  std::stringstream s;
  s << out.rdbuf();
  *printed = s.str();
}

// Every number a program printed, in order.
inline std::vector<double> PrintedNumbers(const std::string& printed) {
  std::istringstream in(printed);
  std::vector<double> got;
  for (double x; in >> x;) got.push_back(x);
  return got;
}

// Calls f(name, values) for each array of the table: its axes, then its
// outputs.
template <typename F>
void ForEachArray(const Table& t, F f) {
  for (const auto& a : t.axes) f(a.name, a.values);
  for (const auto& o : t.outputs) f(o.name, o.values);
}

}  // namespace fluxcal::tables

#endif  // FLUXCAL_TESTS_TABLES_C_UNIT_H_
