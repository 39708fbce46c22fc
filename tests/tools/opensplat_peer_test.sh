#!/usr/bin/env bash
# benchmarks/peers/opensplat.sh: without an OpenSplat binary it explains how to build one and
# skips (exit 0); --ours_only runs our side on a tiny scene and writes a table row per count.
set -euo pipefail
SOURCE=$1
BUILD=$2
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
cd "$SOURCE"
text=$(env -u OPENSPLAT MGSR_BUILD_DIR="$BUILD" bash benchmarks/peers/opensplat.sh)
grep -q "skipped: set OPENSPLAT" <<<"$text" || { echo "no skip message: $text"; exit 1; }
grep -q "GPU_RUNTIME=CPU" <<<"$text" || { echo "no build instructions: $text"; exit 1; }
if ! command -v python3 >/dev/null; then
  echo "python3 absent: the --ours_only run is not checked"
  exit 0
fi
MGSR_BUILD_DIR="$BUILD" bash benchmarks/peers/opensplat.sh --ours_only --size 48 --views 8 \
  --iterations 20 --counts 300,600 --output "$OUT" >/dev/null
rows=$(grep -c 'MGSR-CPU `--method 3dgs`' "$OUT/opensplat.md")
[ "$rows" -eq 2 ] || { cat "$OUT/opensplat.md"; echo "expected 2 rows"; exit 1; }
# The count is held: every row ends with as many Gaussians as it started.
grep -q '| 300 | MGSR-CPU `--method 3dgs` | [0-9.]* | 300 |' "$OUT/opensplat.md" ||
  { cat "$OUT/opensplat.md"; echo "count not held"; exit 1; }
echo "ok"
