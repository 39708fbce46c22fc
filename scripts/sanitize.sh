#!/usr/bin/env bash
# The fast tests under AddressSanitizer and UndefinedBehaviorSanitizer: a separate build
# (build_sanitize, -O1 -g1, -DMGSR_SANITIZE=ON, generic x86-64 so Eigen's alignment matches the
# packaged Ceres' for the whole build) of the libraries and the test binary, then every test
# that runs in-process (renderers and their gradients, losses, I/O parsers, metrics, fusion,
# checkpoints, short solves), in two processes side by side. (The test files themselves are built
# with AddressSanitizer alone: tests/CMakeLists.txt.) The slow end-to-end and command-line
# tests run in the normal build. (-g1: line tables, all a sanitizer's report needs, and a quarter
# less compile time than -g for the test files.)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${MGSR_SANITIZE_BUILD_DIR:-build_sanitize}
if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_FLAGS_DEBUG="-O1 -g1" \
    -DMGSR_SANITIZE=ON -DMGSR_NATIVE_ARCH=OFF -DMGSR_BUILD_BENCHMARKS=OFF >/dev/null
fi
cmake --build "$BUILD_DIR" -j "$(nproc)" --target mgsr_tests
# Tests that drive the command-line tools, the harness or the installed library, and the long
# solves: covered by the normal build's ctest.
SLOW='Cli*:CliHelp*:Fuzz*:ColmapPipeline*:Harness*:InstalledLibrary*:SurfaceOffset*:LossSpike*'
SLOW+=':SharedScene*:*ExposureCompensationLearnsKnownGains*'
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:abort_on_error=1:strict_string_checks=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
export LSAN_OPTIONS=${LSAN_OPTIONS:-suppressions=$PWD/scripts/lsan_suppressions.txt}
# Two shards side by side, one per core (gtest's own sharding: each process runs every other test);
# each writes its log, shown when both have finished. OpenMP threads that wait passively: two
# processes that busy-wait slow each other down many times over (as under ctest).
export OMP_WAIT_POLICY=passive
SHARDS=2
LOG_DIR=$(mktemp -d)
trap 'rm -rf "$LOG_DIR"' EXIT
pids=()
for ((i = 0; i < SHARDS; ++i)); do
  GTEST_TOTAL_SHARDS=$SHARDS GTEST_SHARD_INDEX=$i \
    "$BUILD_DIR/tests/mgsr_tests" --gtest_filter="-$SLOW" --gtest_brief=1 >"$LOG_DIR/$i.log" 2>&1 &
  pids+=($!)
done
failed=0
for ((i = 0; i < SHARDS; ++i)); do
  wait "${pids[$i]}" || failed=1
done
for ((i = 0; i < SHARDS; ++i)); do
  echo "--- sanitizer tests, shard $((i + 1)) of $SHARDS"
  cat "$LOG_DIR/$i.log"
done
exit $failed
