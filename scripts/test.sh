#!/usr/bin/env bash
# The README's test command: installs what is missing (apt), configures,
# builds, fuzzes the set readers for a bounded time (libFuzzer, clang from
# Debian) and runs every GoogleTest suite through ctest (fuzz_test there
# replays the kept crash corpus and runs GoogleTest-driven mutations).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
bash scripts/build.sh
FUZZ_TIME=${FUZZ_TIME:-45} FUZZ_OUT="$BUILD_DIR-fuzz" bash scripts/fuzz.sh >&2
cd "$BUILD_DIR"
ctest --output-on-failure -j"$(nproc)" "$@"
