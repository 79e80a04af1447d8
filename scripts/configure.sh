#!/usr/bin/env bash
# Configures ${BUILD_DIR:-build} for this tree, only when it needs it, so
# that a build that exists is reused (scripts/demo.sh builds on it):
#   - no CMakeCache.txt: installs missing Debian packages
#     (scripts/install-deps.sh; not with --no-deps) and configures (Ninja,
#     ${BUILD_TYPE:-RelWithDebInfo}, ccache as compiler launcher when
#     installed);
#   - a CMakeCache.txt of THIS tree: nothing (the build re-runs CMake by
#     itself when a CMakeLists.txt changed);
#   - a CMakeCache.txt of ANOTHER path (the tree was copied or moved with its
#     build directory): CMake refuses it ("does not match the source ... used
#     to generate cache"), and building with it would build the other tree.
#     It is moved aside to CMakeCache.txt.stale, the path-bound CMakeFiles/
#     removed, and the directory configured for this tree with the old build
#     type. Objects stay (ccache reuses what it can); nothing else is deleted.
# Prints the steps on stderr. Exit 1 when configuring fails.
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${BUILD_DIR:-build}
DEPS=1
[ "${1:-}" = "--no-deps" ] && DEPS=0
here=$(pwd -P)
cache="$BUILD_DIR/CMakeCache.txt"
type=${BUILD_TYPE:-RelWithDebInfo}

if [ -f "$cache" ]; then
  home=$(sed -n 's/^CMAKE_HOME_DIRECTORY:INTERNAL=//p' "$cache")
  home_real=$(cd "$home" 2>/dev/null && pwd -P || true)
  if [ -n "$home_real" ] && [ "$home_real" = "$here" ]; then
    echo "configure: reusing $BUILD_DIR/ (configured for this tree)" >&2
    exit 0
  fi
  old_type=$(sed -n 's/^CMAKE_BUILD_TYPE:[A-Z]*=//p' "$cache")
  [ -n "$old_type" ] && [ -z "${BUILD_TYPE:-}" ] && type=$old_type
  echo "configure: $BUILD_DIR/ was configured for ${home:-an unknown path}, not for $here (a copied or moved tree):" \
       "its cache moved to $cache.stale, $BUILD_DIR/CMakeFiles/ removed, reconfiguring ($type)" >&2
  mv -f "$cache" "$cache.stale"
  rm -rf "$BUILD_DIR/CMakeFiles"
else
  echo "configure: no build in $BUILD_DIR/ yet: configuring ($type)" >&2
fi

[ "$DEPS" = 1 ] && bash scripts/install-deps.sh
launcher=()
command -v ccache >/dev/null 2>&1 && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
cmake -S . -B "$BUILD_DIR" -G Ninja -DCMAKE_BUILD_TYPE="$type" "${launcher[@]}" >&2
