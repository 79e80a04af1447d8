#!/usr/bin/env bash
# scripts/configure.sh, which scripts/demo.sh builds on, in a copied tree:
#   1. a copy of the sources whose build/ holds a CMake cache of another
#      path (as after `cp -r` of a built tree): the cache is moved to
#      CMakeCache.txt.stale, the directory configured for the copy with the
#      old build type, other files in build/ left alone;
#   2. run again: the build is reused, nothing configured.
# Configures only (a few seconds); builds nothing; installs nothing (--no-deps).
# usage: configure_test.sh SOURCE_DIR
set -euo pipefail
SRC=$1
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT
fail() { echo "configure_test: FAIL: $*" >&2; exit 1; }

mkdir -p "$W/copy"
tar -C "$SRC" --exclude=./build --exclude='./build-*' --exclude=./out --exclude=./.git -cf - . | tar -C "$W/copy" -xf -
mkdir -p "$W/copy/build/CMakeFiles"
cat > "$W/copy/build/CMakeCache.txt" <<CACHE
CMAKE_BUILD_TYPE:STRING=Debug
CMAKE_HOME_DIRECTORY:INTERNAL=/nonexistent/original/tree
CACHE
echo keep > "$W/copy/build/object.o"

BUILD_DIR=build bash "$W/copy/scripts/configure.sh" --no-deps 2> "$W/first.err" || { cat "$W/first.err" >&2; fail "configure of the copy failed"; }
grep -q "configured for /nonexistent/original/tree" "$W/first.err" || fail "no word of the stale cache: $(cat "$W/first.err")"
home=$(sed -n 's/^CMAKE_HOME_DIRECTORY:INTERNAL=//p' "$W/copy/build/CMakeCache.txt")
[ "$(cd "$home" && pwd -P)" = "$(cd "$W/copy" && pwd -P)" ] || fail "cache home $home, expected the copy $W/copy"
grep -q '^CMAKE_BUILD_TYPE:STRING=Debug$' "$W/copy/build/CMakeCache.txt" || fail "the old build type was not kept"
[ -f "$W/copy/build/CMakeCache.txt.stale" ] || fail "the stale cache was not kept aside"
[ "$(cat "$W/copy/build/object.o")" = keep ] || fail "a file of the build directory was touched"
[ -f "$W/copy/build/build.ninja" ] || fail "no build.ninja after configuring"

before=$(cksum < "$W/copy/build/CMakeCache.txt")
BUILD_DIR=build bash "$W/copy/scripts/configure.sh" --no-deps 2> "$W/second.err" || fail "second run failed: $(cat "$W/second.err")"
grep -q "reusing build/" "$W/second.err" || fail "the second run did not reuse the build: $(cat "$W/second.err")"
[ "$(cksum < "$W/copy/build/CMakeCache.txt")" = "$before" ] || fail "the second run reconfigured"
echo "configure_test: ok" >&2
