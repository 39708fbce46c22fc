#!/usr/bin/env bash
# One command for the main job on a built-in demo scene: install, build, generate a synthetic
# specular object under varying light, reconstruct it, report.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install_deps.sh
bash scripts/build.sh
BIN=${MGSR_BUILD_DIR:-build}/tools
OUT=${1:-demo_out}
"$BIN/mgsr_synth" --output "$OUT/scene" --shape dented --num_views 48 --width 128 --height 128
"$BIN/mgsr_solve" --workspace "$OUT/scene" --output "$OUT/result" --overwrite --preset fast --log_every 250
echo "demo: scene in $OUT/scene (ground truth: $OUT/scene/gt/), results in $OUT/result (mesh.ply, renders/, metrics.json)"
