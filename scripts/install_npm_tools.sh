#!/usr/bin/env bash
# Installs the third-party readers the compatibility tests run against our outputs (npm packages
# pinned in tests/third_party/package.json and package-lock.json) into BUILD/npm_tools. Never fails
# the caller: without npm or the registry it says so in one line, and those tests then skip with
# the same reason.
set -uo pipefail
cd "$(dirname "$0")/.."
dest="${MGSR_BUILD_DIR:-build}/npm_tools"
if ! command -v npm >/dev/null 2>&1; then
  echo "[npm_tools] npm is not installed: the third-party compatibility tests (splat-transform, gltf-validator) will be skipped"
  exit 0
fi
mkdir -p "$dest"
if cmp -s tests/third_party/package-lock.json "$dest/package-lock.json" &&
  [ -x "$dest/node_modules/.bin/splat-transform" ] &&
  [ -f "$dest/node_modules/gltf-validator/package.json" ]; then
  echo "[npm_tools] splat-transform and gltf-validator present"
  exit 0
fi
cp tests/third_party/package.json tests/third_party/package-lock.json "$dest/"
# --ignore-scripts: the packages' install scripts build GPU back-ends the tests do not use.
if (cd "$dest" && npm ci --no-audit --no-fund --ignore-scripts --loglevel=error >npm_ci.log 2>&1); then
  echo "[npm_tools] installed splat-transform $(cd "$dest" && node -p 'require("./node_modules/@playcanvas/splat-transform/package.json").version')," \
    "gltf-validator $(cd "$dest" && node -p 'require("./node_modules/gltf-validator/package.json").version')"
else
  echo "[npm_tools] npm ci failed (see $dest/npm_ci.log): the third-party compatibility tests will be skipped"
  rm -f "$dest/package-lock.json"
fi
exit 0
