#!/usr/bin/env bash
# Configures and builds fluxcal into ${BUILD_DIR:-build} (Ninja, all cores).
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
bash scripts/install-deps.sh
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE=${BUILD_TYPE:-RelWithDebInfo} >&2
cmake --build "$BUILD_DIR" -j"$(nproc)" >&2
