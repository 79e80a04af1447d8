#!/usr/bin/env bash
# libFuzzer over the recording-set readers (tests/fuzz/recording_fuzz.h):
# builds the io library and the entry point with clang, ASan and UBSan, then
# runs the kept corpus plus new mutations.
#   bash scripts/fuzz.sh                 # 1,000,000 executions
#   FUZZ_RUNS=0 FUZZ_TIME=60 bash scripts/fuzz.sh   # 60 s instead
# New crashers land in tests/fuzz/corpus/ (crash-*) so that fuzz_test keeps
# them as regression tests. Needs Debian's clang and libclang-rt-14-dev.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${FUZZ_OUT:-build-fuzz}
RUNS=${FUZZ_RUNS:-1000000}
TIME=${FUZZ_TIME:-0}
CXX=${FUZZ_CXX:-clang++}
if ! command -v "$CXX" >/dev/null; then
  echo "fuzz.sh: $CXX not found (apt-get install clang libclang-rt-14-dev)" >&2
  exit 1
fi
mkdir -p "$OUT" "$OUT/corpus"
ABSL_LIBS=$(pkg-config --libs absl_status absl_statusor absl_strings absl_str_format)
set -x
"$CXX" -std=c++20 -O1 -g -fsanitize=fuzzer,address,undefined -fno-sanitize-recover=undefined \
  -I. io/csv.cc io/manifest.cc io/recording_set.cc tests/fuzz/recording_fuzz.cc tests/fuzz/libfuzzer_main.cc \
  $ABSL_LIBS -o "$OUT/recording_fuzzer"
set +x
ARGS=(-artifact_prefix=tests/fuzz/corpus/crash- -print_final_stats=1 -max_len=65536)
if [ "$TIME" != "0" ]; then ARGS+=(-max_total_time="$TIME"); else ARGS+=(-runs="$RUNS"); fi
"$OUT/recording_fuzzer" "${ARGS[@]}" "$OUT/corpus" tests/fuzz/corpus
