#!/usr/bin/env bash
# Configures and builds MGSR-CPU (Release, with the MPI view group: mgsr_solve under mpirun) into
# ./build. Used by demo.sh and test.sh. (scripts/sanitize.sh builds without MPI: both ways.)
set -euo pipefail
cd "$(dirname "$0")/.."
BUILD_DIR=${MGSR_BUILD_DIR:-build}
if [ ! -f "$BUILD_DIR/CMakeCache.txt" ]; then
  cmake -S . -B "$BUILD_DIR" -DCMAKE_BUILD_TYPE=Release -DMGSR_WITH_MPI=ON >/dev/null
fi
cmake --build "$BUILD_DIR" -j "$(nproc)"
