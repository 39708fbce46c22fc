#!/usr/bin/env bash
# One command for the test suite on a fresh Debian 12 machine: install, check the formatting, build
# (warnings are errors) while the third-party readers of the compatibility tests install, run ctest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/check_format.sh
# The third-party readers download while the tree compiles (the one waits on the network, the
# other on the cores); their script never fails, and its log is shown after the build.
npm_log=$(mktemp)
trap 'rm -f "$npm_log"' EXIT
bash scripts/install_npm_tools.sh >"$npm_log" 2>&1 &
npm_pid=$!
bash scripts/build.sh
wait "$npm_pid" || true
cat "$npm_log"
cd "${MGSR_BUILD_DIR:-build}"
ctest --output-on-failure -j "$(nproc)"
