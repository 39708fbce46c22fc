#!/usr/bin/env bash
# The installed library as another project sees it: installs this build into a scratch prefix,
# configures and builds examples/custom_loss against it with find_package(mgsr), and runs it (a new
# loss term, registered in one line and switched on by one row of losses.json, trains a small
# scene). Usage: custom_loss_example.sh SOURCE_DIR BUILD_DIR
set -euo pipefail
src=$1
build=$2
scratch="$build/install_test"
rm -rf "$scratch"
cmake --install "$build" --prefix "$scratch/prefix" > "$scratch.install.log" 2>&1 ||
  { cat "$scratch.install.log"; exit 1; }
# Only public headers: the pixel loops' internals (instruction-set dependent vectors) stay out.
for internal in render/simd16.h render/raster_scratch.h render/projection_lanes.h; do
  if [ -e "$scratch/prefix/include/mgsr/$internal" ]; then
    echo "internal header installed: mgsr/$internal" >&2
    exit 1
  fi
done
test -e "$scratch/prefix/include/mgsr/render/gaussian_renderer.h"
cmake -S "$src/examples/custom_loss" -B "$scratch/example" -DCMAKE_PREFIX_PATH="$scratch/prefix"
cmake --build "$scratch/example" -j 2
out=$("$scratch/example/custom_loss" "$src/examples/custom_loss/losses.json" "$scratch/work")
echo "$out"
grep -q "crisp_alpha trained in" <<< "$out"
# Nothing of the source or build tree leaks into the installed package's targets.
if grep -rq -e "$src/mgsr" -e "$src/solvers" "$scratch/prefix/lib/cmake/mgsr"; then
  echo "the installed targets name the source tree" >&2
  exit 1
fi
