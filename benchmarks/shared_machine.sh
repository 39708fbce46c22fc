#!/usr/bin/env bash
# One training run under a given OpenMP wait setting, on an idle machine or with a busy loop
# holding a core beside it (docs/performance.md, "Shared machines"):
#
#   bash benchmarks/shared_machine.sh SCENE THREADS SETTING LOAD [mgsr_solve flags]
#
# SETTING: default (libgomp's own), passive (OMP_WAIT_POLICY=PASSIVE), tools (the tools' own
# choice), or spinN (GOMP_SPINCOUNT=N). LOAD: idle or busy. Prints the scene, threads, setting,
# load and the training seconds (warm-up + mutual, from metrics.json).
set -euo pipefail
cd "$(dirname "$0")/.."
[ $# -ge 4 ] || { sed -n 2,10p "$0"; exit 2; }
scene=$1 threads=$2 setting=$3 load=$4
shift 4
BIN=${MGSR_BUILD_DIR:-build}/tools
out=${MGSR_BUILD_DIR:-build}/shared_machine/$(basename "$scene")_${threads}_${setting}_${load}
mkdir -p "$(dirname "$out")"
case "$setting" in
  default) envs=(MGSR_OPENMP_WAIT_SET=1) ;;  # the tools leave libgomp alone
  passive) envs=(OMP_WAIT_POLICY=PASSIVE) ;;
  tools) envs=() ;;
  spin*) envs=(GOMP_SPINCOUNT="${setting#spin}") ;;
  *) echo "shared_machine.sh: unknown setting $setting" >&2; exit 2 ;;
esac
busy=""
if [ "$load" = busy ]; then
  ( while :; do :; done ) &
  busy=$!
fi
trap '[ -n "$busy" ] && kill "$busy" 2>/dev/null || true' EXIT
env -u OMP_WAIT_POLICY -u GOMP_SPINCOUNT -u MGSR_OPENMP_WAIT_SET "${envs[@]}" OMP_NUM_THREADS="$threads" \
  "$BIN/mgsr_solve" --workspace "$scene" --output "$out" --overwrite --preset fast \
  --log_every 100000 --eval_every 0 --checkpoint_every 0 "$@" >"$out.log" 2>&1
python3 -c "import json,sys; m=json.load(open(sys.argv[1])); s=m['seconds']; print(*sys.argv[2:], round(s['warmup'] + s['mutual'], 1), 's')" \
  "$out/metrics.json" "$(basename "$scene")" "$threads" "$setting" "$load"
