#!/usr/bin/env bash
# Side by side with OpenSplat (https://github.com/pierotofy/OpenSplat), the nearest CPU peer: its
# libtorch CPU backend against our plain 3DGS (`mgsr_solve --method 3dgs`) on the same COLMAP
# workspace, at the same resolution, for the same number of iterations, at fixed Gaussian counts.
# OpenSplat is AGPL: it is never part of this repository; give a binary you built:
#
#   OPENSPLAT=/path/to/opensplat bash benchmarks/peers/opensplat.sh [options]
#
# Without OPENSPLAT it prints how to build one and skips (exit 0). --ours_only runs our side alone
# (what the test suite checks). Options: --size PX (256), --views N (48), --iterations N (300),
# --counts LIST (3000,30000), --output DIR (build/peers_opensplat), --equal_time (the second
# table instead: quality at equal wall time, below).
#
# How the runs are made equal: one synthetic object (mgsr_synth, constant light, no exposure
# changes, RGB photos on a grey backdrop without masks: OpenSplat reads RGB and renders on its own
# background colour, so a transparent backdrop would score its background), one COLMAP workspace whose sparse points are the initial Gaussians (--num_points =
# the count), the first view withheld from both (OpenSplat --val-image, our split.txt). OpenSplat
# densifies only after its warm-up (500 iterations by default) and ours holds the count with the
# MCMC strategy's cap, so both train exactly `count` Gaussians for `iterations` steps. Reported:
# seconds per iteration (training only: ours from metrics.json, OpenSplat's whole run minus
# nothing, so its figure includes loading and the withheld view's render every 10 steps that
# --val-render makes), Gaussians at the end, peak memory (GNU time), PSNR of the withheld view.
# The table goes to OUTPUT/opensplat.md, for BENCHMARKS.md.
#
# --equal_time: quality at equal wall time. On one such scene (--counts' first entry as its SfM
# points), our fast preset runs as plain 3DGS and as MGSR, each with its own schedule and model
# size; each run's whole wall time T is then given to OpenSplat: its own schedule (densification,
# SH degrees; at full resolution, --num-downscales 0 -d 1) cut at the iteration count a 200-step
# probe says fits in T. Reported: wall seconds, iterations, Gaussians, PSNR of the withheld view
# (OUTPUT/opensplat_equal_time.md).
set -euo pipefail
cd "$(dirname "$0")/../.."
SIZE=256
VIEWS=48
ITERATIONS=300
COUNTS=3000,30000
OUT=build/peers_opensplat
OURS_ONLY=0
EQUAL_TIME=0
while [ $# -gt 0 ]; do
  case "$1" in
    --size) SIZE=$2; shift 2 ;;
    --views) VIEWS=$2; shift 2 ;;
    --iterations) ITERATIONS=$2; shift 2 ;;
    --counts) COUNTS=$2; shift 2 ;;
    --output) OUT=$2; shift 2 ;;
    --ours_only) OURS_ONLY=1; shift ;;
    --equal_time) EQUAL_TIME=1; shift ;;
    *) echo "opensplat.sh: unknown option $1" >&2; exit 2 ;;
  esac
done

if [ $OURS_ONLY -eq 0 ] && { [ -z "${OPENSPLAT:-}" ] || [ ! -x "${OPENSPLAT}" ]; }; then
  cat <<'EOF'
[opensplat] skipped: set OPENSPLAT to an OpenSplat binary to compare with it.
To build one on Debian 12 (CPU only; OpenSplat is AGPL, keep it outside this repository):
  sudo apt-get install libtorch-dev libopencv-dev nlohmann-json3-dev libnanoflann-dev libglm-dev
  git clone https://github.com/pierotofy/OpenSplat && cd OpenSplat && mkdir build && cd build
  # its CMakeLists fetches nlohmann_json, nanoflann and glm with FetchContent: point each at the
  # Debian package instead, e.g. -DFETCHCONTENT_TRY_FIND_PACKAGE_MODE=ALWAYS (CMake >= 3.24) or
  # by replacing the FetchContent_Declare blocks with find_package(... REQUIRED)
  cmake .. -DCMAKE_BUILD_TYPE=Release -DGPU_RUNTIME=CPU -DCMAKE_PREFIX_PATH=/usr/lib/x86_64-linux-gnu/cmake/Torch
  make -j"$(nproc)"
then: OPENSPLAT=$PWD/opensplat bash benchmarks/peers/opensplat.sh
EOF
  exit 0
fi
command -v python3 >/dev/null || { echo "opensplat.sh: needs python3 (reads metrics.json)" >&2; exit 1; }
TIME=/usr/bin/time  # OpenSplat's peak memory (ours is in its metrics.json)
if [ $OURS_ONLY -eq 0 ] && [ ! -x $TIME ]; then
  echo "opensplat.sh: needs GNU time (/usr/bin/time, Debian package time)" >&2
  exit 1
fi
bash scripts/build.sh >/dev/null
BIN=${MGSR_BUILD_DIR:-build}/tools
mkdir -p "$OUT"
TABLE="$OUT/opensplat.md"
{
  echo "| Gaussians | tool | s / iteration | Gaussians at the end | peak memory (MB) | PSNR, withheld view |"
  echo "| ---: | --- | ---: | ---: | ---: | ---: |"
} > "$TABLE"

# Peak resident memory (MB) from a GNU time -v log.
peak_mb() { awk -F': ' '/Maximum resident set size/ {printf "%.0f", $2 / 1024}' "$1"; }

# The synthetic scene with $1 SfM points into $SCENE; sets VAL, its withheld view.
make_scene() {
  rm -rf "$SCENE"
  "$BIN/mgsr_synth" --output "$SCENE" --width "$SIZE" --height "$SIZE" --num_views "$VIEWS" \
    --num_points "$1" --varying_light=false --exposure_stops 0 --test_every "$VIEWS" \
    --masks=false \
    --seed 1 >/dev/null
  VAL=$(head -n 1 "$SCENE/split.txt")
}

# OpenSplat for $2 iterations into $OUT/$1 (its own defaults besides full resolution and the
# withheld view); sets SECONDS_TAKEN (wall) and PSNR (its render of VAL, scored with mgsr_eval).
run_opensplat() {
  local name=$1 n=$2
  rm -rf "${OUT:?}/$name" && mkdir -p "$OUT/$name/val"
  local start end render
  start=$(date +%s.%N)
  # --num-downscales 0 -d 1: OpenSplat's defaults train at a quarter of the image size until step
  # 3,000 (and older versions at half size); at those it would not be the same resolution as ours.
  $TIME -v "$OPENSPLAT" "$SCENE" -n "$n" --num-downscales 0 -d 1 --val --val-image "$VAL" \
    --val-render "$OUT/$name/val" -o "$OUT/$name/splat.ply" \
    >"$OUT/$name.log" 2>"$OUT/$name.time"
  end=$(date +%s.%N)
  SECONDS_TAKEN=$(python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$start" "$end")
  PSNR="n/a"
  render=$(ls -t "$OUT/$name/val"/*.png 2>/dev/null | head -n 1 || true)
  if [ -n "$render" ]; then
    mkdir -p "$OUT/$name/score/render" "$OUT/$name/score/truth"
    cp "$render" "$OUT/$name/score/render/$VAL"
    cp "$SCENE/images/$VAL" "$OUT/$name/score/truth/$VAL"
    PSNR=$("$BIN/mgsr_eval" --renders "$OUT/$name/score/render" \
      --gt_images "$OUT/$name/score/truth" | awk '$1 == "mean" {print $2 " dB"; exit}')
  fi
}

if [ $EQUAL_TIME -eq 1 ]; then
  [ $OURS_ONLY -eq 1 ] && { echo "opensplat.sh: --equal_time needs OpenSplat (not --ours_only)" >&2; exit 2; }
  TABLE="$OUT/opensplat_equal_time.md"
  COUNT=${COUNTS%%,*}
  SCENE="$OUT/scene_equal_time"
  make_scene "$COUNT"
  # OpenSplat's seconds per iteration on this scene, from a probe (loading included).
  run_opensplat opensplat_probe 200
  PER_IT=$(python3 -c "import sys; print(float(sys.argv[1]) / 200)" "$SECONDS_TAKEN")
  {
    echo "| tool, schedule | wall s | iterations | Gaussians at the end | PSNR, withheld view |"
    echo "| --- | ---: | ---: | ---: | ---: |"
  } > "$TABLE"
  for METHOD in 3dgs mgsr; do
    rm -rf "$OUT/ours_equal_$METHOD"
    START=$(date +%s.%N)
    "$BIN/mgsr_solve" --workspace "$SCENE" --output "$OUT/ours_equal_$METHOD" --preset fast \
      --method "$METHOD" --eval_every 0 --checkpoint_every 0 --log_every 100000 \
      >"$OUT/ours_equal_$METHOD.log" 2>&1
    END=$(date +%s.%N)
    WALL=$(python3 -c "import sys; print(f'{float(sys.argv[2]) - float(sys.argv[1]):.1f}')" "$START" "$END")
    python3 - "$OUT/ours_equal_$METHOD/metrics.json" "$METHOD" "$WALL" >>"$TABLE" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
it = sum(v for v in m["iterations"].values() if not isinstance(v, bool))
label = "plain 3DGS" if sys.argv[2] == "3dgs" else "MGSR"
print(f"| MGSR-CPU {label}, `--preset fast` | {float(sys.argv[3]):.1f} | {it:,} | "
      f"{m['counts']['gaussians']:,} | {m['test']['psnr']:.2f} dB |")
PY
    N=$(python3 -c "import sys; print(max(1, int(float(sys.argv[1]) / float(sys.argv[2]))))" "$WALL" "$PER_IT")
    run_opensplat "opensplat_equal_$METHOD" "$N"
    GAUSSIANS=$(awk '/^element vertex/ {print $3; exit}' "$OUT/opensplat_equal_$METHOD/splat.ply" 2>/dev/null || true)
    echo "| OpenSplat, its schedule cut at the same time | $SECONDS_TAKEN | $N | ${GAUSSIANS:-?} | $PSNR |" >>"$TABLE"
  done
  echo "[opensplat] probe: $PER_IT s per iteration; table: $TABLE"
  cat "$TABLE"
  exit 0
fi

for COUNT in ${COUNTS//,/ }; do
  SCENE="$OUT/scene_$COUNT"
  make_scene "$COUNT"

  # Ours: plain 3DGS, the count held at COUNT (the paper preset keeps up to 100,000 initial points).
  rm -rf "$OUT/ours_$COUNT"
  "$BIN/mgsr_solve" --workspace "$SCENE" --output "$OUT/ours_$COUNT" --preset paper \
    --method 3dgs --warmup_min_iterations 0 --warmup_max_iterations "$ITERATIONS" \
    --mutual_iterations 0 --density mcmc --max_gaussians "$COUNT" \
    --exposure off --eval_every 0 --checkpoint_every 0 --log_every 100000 \
    >"$OUT/ours_$COUNT.log" 2>&1
  python3 - "$OUT/ours_$COUNT/metrics.json" "$COUNT" >>"$TABLE" <<'PY'
import json, sys
m = json.load(open(sys.argv[1]))
it = max(1, m["iterations"]["warmup_3d"])
print(f"| {int(sys.argv[2]):,} | MGSR-CPU `--method 3dgs` | {m['seconds']['warmup'] / it:.4f} | "
      f"{m['counts']['gaussians']:,} | {m['peak_memory_mb']:.0f} | {m['test']['psnr']:.2f} dB |")
PY

  [ $OURS_ONLY -eq 1 ] && continue
  # OpenSplat on the same workspace, the same view withheld; its render of that view is scored
  # against the photo with mgsr_eval.
  run_opensplat "opensplat_$COUNT" "$ITERATIONS"
  python3 -c "import sys; t, n = float(sys.argv[1]), float(sys.argv[3]); print(f'| {int(sys.argv[2]):,} | OpenSplat (CPU) | {t / n:.4f} | {int(sys.argv[2]):,} | {sys.argv[4]} | {sys.argv[5]} |')" \
    "$SECONDS_TAKEN" "$COUNT" "$ITERATIONS" "$(peak_mb "$OUT/opensplat_$COUNT.time")" "$PSNR" \
    >>"$TABLE"
done
echo "[opensplat] table: $TABLE"
cat "$TABLE"
