#!/usr/bin/env bash
# Installs the third-party readers the compatibility tests run against our outputs: npm packages
# pinned in tests/third_party/package.json and package-lock.json (splat-transform, the glTF
# validator, the Spark web viewer and three.js) into BUILD/npm_tools, and Debian's chromium for the
# viewer. Never fails the caller: without npm, Chromium or the registries it says so in one line,
# and those tests then skip with the same reason.
set -uo pipefail
cd "$(dirname "$0")/.."
dest="${MGSR_BUILD_DIR:-build}/npm_tools"

# The web viewer of SparkViewerInteropTest runs in Debian's Chromium (headless, software WebGL).
if command -v chromium >/dev/null 2>&1; then
  echo "[npm_tools] chromium present"
else
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  if { $SUDO apt-get update -qq &&
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends chromium; } \
    >/tmp/mgsr_install_chromium.log 2>&1; then
    echo "[npm_tools] installed $(chromium --version 2>/dev/null | head -1)"
  else
    echo "[npm_tools] apt-get install chromium failed (see /tmp/mgsr_install_chromium.log): the web-viewer test will be skipped"
  fi
fi
if ! command -v npm >/dev/null 2>&1; then
  echo "[npm_tools] npm is not installed: the third-party compatibility tests (splat-transform, gltf-validator, Spark) will be skipped"
  exit 0
fi
mkdir -p "$dest"
if cmp -s tests/third_party/package-lock.json "$dest/package-lock.json" &&
  [ -x "$dest/node_modules/.bin/splat-transform" ] &&
  [ -f "$dest/node_modules/gltf-validator/package.json" ] &&
  [ -f "$dest/node_modules/@sparkjsdev/spark/package.json" ]; then
  echo "[npm_tools] splat-transform, gltf-validator and spark present"
  exit 0
fi
cp tests/third_party/package.json tests/third_party/package-lock.json "$dest/"
# --ignore-scripts: the packages' install scripts build GPU back-ends the tests do not use.
if (cd "$dest" && npm ci --no-audit --no-fund --ignore-scripts --loglevel=error >npm_ci.log 2>&1); then
  echo "[npm_tools] installed splat-transform $(cd "$dest" && node -p 'require("./node_modules/@playcanvas/splat-transform/package.json").version')," \
    "gltf-validator $(cd "$dest" && node -p 'require("./node_modules/gltf-validator/package.json").version')," \
    "spark $(cd "$dest" && node -p 'require("./node_modules/@sparkjsdev/spark/package.json").version')"
else
  echo "[npm_tools] npm ci failed (see $dest/npm_ci.log): the third-party compatibility tests will be skipped"
  rm -f "$dest/package-lock.json"
fi
exit 0
