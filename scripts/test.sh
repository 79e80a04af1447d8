#!/usr/bin/env bash
# The README's test command: installs what is missing (apt), configures,
# builds and runs every GoogleTest suite through ctest.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
bash scripts/build.sh
cd "$BUILD_DIR"
ctest --output-on-failure -j"$(nproc)" "$@"
