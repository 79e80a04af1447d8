// Progress on stderr, one helper for every command that reports it
// (docs/cli.md, "Output"). On a terminal an update rewrites the line in
// place ("\r", a newline after the last); anywhere else (a pipe, a log
// file, a CI runner) every update is a line of its own, so that logs read
// "fit: identifying point 1/42\nfit: identifying point 2/42\n..." rather
// than one run-on line.
#ifndef FLUXCAL_CLI_SUPPORT_PROGRESS_H_
#define FLUXCAL_CLI_SUPPORT_PROGRESS_H_

#include <cstddef>
#include <cstdio>
#include <functional>
#include <string>

namespace fluxcal::cli {

// Writes "<label> k/n" to `to` for update k (0-based) of n. `terminal`:
// rewrite in place; by default whether `to` is a terminal (isatty).
class ProgressLine {
 public:
  explicit ProgressLine(std::string label, std::FILE* to = stderr);
  ProgressLine(std::string label, std::FILE* to, bool terminal);
  void Update(size_t k, size_t n) const;
  // The form the identification options take (ident::IdentifyOptions::progress).
  std::function<void(size_t, size_t)> Callback() const;

 private:
  std::string label_;
  std::FILE* to_;
  bool terminal_;
};

}  // namespace fluxcal::cli

#endif  // FLUXCAL_CLI_SUPPORT_PROGRESS_H_
