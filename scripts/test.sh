#!/usr/bin/env bash
# One command for the test suite on a fresh Debian 12 machine: install, check the formatting, build
# (warnings are errors), install the third-party readers of the compatibility tests, run ctest.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/check_format.sh
bash scripts/build.sh
bash scripts/install_npm_tools.sh
cd "${MGSR_BUILD_DIR:-build}"
ctest --output-on-failure -j "$(nproc)"
