#!/usr/bin/env bash
# Installs the third-party readers the compatibility tests run against our outputs: npm packages
# pinned in tests/third_party/package.json and package-lock.json (splat-transform, the glTF
# validator, the Spark web viewer and three.js) into BUILD/npm_tools, and Debian's chromium (for
# the viewer), ffmpeg and python3-open3d. Never fails the caller: without npm, a package or the registries it says
# so in one line, and those tests then skip (or check less) with the same reason.
set -uo pipefail
cd "$(dirname "$0")/.."
dest="${MGSR_BUILD_DIR:-build}/npm_tools"

# Debian packages the compatibility tests drive, best effort: Chromium for the web viewer of
# SparkViewerInteropTest (headless, software WebGL), ffmpeg for mgsr_render's orbit.mp4, Open3D's
# Python package as a reader of our meshes.
apt_best_effort() {  # PACKAGE CHECK-COMMAND WHAT-SKIPS
  if eval "$2" >/dev/null 2>&1; then
    echo "[npm_tools] $1 present"
    return
  fi
  local sudo=""
  if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  if { $sudo apt-get update -qq &&
    DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "$1"; } \
    >"/tmp/mgsr_install_$1.log" 2>&1; then
    echo "[npm_tools] installed $1"
  else
    echo "[npm_tools] apt-get install $1 failed (see /tmp/mgsr_install_$1.log): $3"
  fi
}
apt_best_effort chromium "command -v chromium" "the web-viewer test will be skipped"
apt_best_effort ffmpeg "command -v ffprobe" "mgsr_render's video is not tested"
apt_best_effort python3-open3d "/usr/bin/python3 -c 'import open3d'" \
  "the Open3D (Python) reader test will be skipped"

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
