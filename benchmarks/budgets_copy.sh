#!/usr/bin/env bash
# Copies a quality-size study made by `mgsr_bench --budgets ... --output DIR` into
# benchmarks/budgets/NAME (its README.md, charts and contact sheet; not the gnuplot scripts and
# data, which name the machine's paths), where benchmarks/notes.md links it from BENCHMARKS.md.
#   bash benchmarks/budgets_copy.sh DIR NAME
set -euo pipefail
src=$1; name=$2
cd "$(dirname "$0")"
[ -f "$src/README.md" ] || { echo "error: $src/README.md: not a report of mgsr_bench" >&2; exit 1; }
rm -rf "budgets/$name"
mkdir -p "budgets/$name/charts" "budgets/$name/contact"
cp "$src/README.md" "$src/results.csv" "$src/context.json" "budgets/$name/"
cp "$src"/charts/*.png "budgets/$name/charts/"
cp "$src"/contact/*.png "budgets/$name/contact/" 2>/dev/null || true
echo "copied to benchmarks/budgets/$name"
