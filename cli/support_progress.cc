#include "cli/support_progress.h"

#include <unistd.h>

#include <utility>

namespace fluxcal::cli {

ProgressLine::ProgressLine(std::string label, std::FILE* to)
    : ProgressLine(std::move(label), to, ::isatty(::fileno(to)) == 1) {}

ProgressLine::ProgressLine(std::string label, std::FILE* to, bool terminal)
    : label_(std::move(label)), to_(to), terminal_(terminal) {}

void ProgressLine::Update(size_t k, size_t n) const {
  if (terminal_) {
    std::fprintf(to_, "\r%s %zu/%zu", label_.c_str(), k + 1, n);
    if (k + 1 >= n) std::fputc('\n', to_);
  } else {
    std::fprintf(to_, "%s %zu/%zu\n", label_.c_str(), k + 1, n);
  }
  std::fflush(to_);
}

std::function<void(size_t, size_t)> ProgressLine::Callback() const {
  return [self = *this](size_t k, size_t n) { self.Update(k, n); };
}

}  // namespace fluxcal::cli
