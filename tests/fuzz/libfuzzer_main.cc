// libFuzzer entry (scripts/fuzz.sh builds it with clang -fsanitize=fuzzer).
#include "tests/fuzz/recording_fuzz.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  fluxcal::fuzz::RunOne(data, size);
  return 0;
}
