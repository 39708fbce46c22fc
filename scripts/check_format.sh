#!/usr/bin/env bash
# Fails (naming the files) when a C++ file of the tree is not as clang-format (.clang-format: Google
# style, 100 columns) would write it. Fix with: git ls-files '*.h' '*.cc' | xargs clang-format -i
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v clang-format >/dev/null; then
  echo "[format] clang-format not found (scripts/install_deps.sh installs it)" >&2
  exit 1
fi
if git rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  mapfile -t files < <(git ls-files '*.h' '*.cc')
else  # a copy without git: the same folders
  mapfile -t files < <(find mgsr solvers tools tests benchmarks examples \( -name '*.h' -o -name '*.cc' \) | sort)
fi
bad=()
for f in "${files[@]}"; do
  clang-format --dry-run -Werror "$f" >/dev/null 2>&1 || bad+=("$f")
done
if [ ${#bad[@]} -gt 0 ]; then
  echo "[format] ${#bad[@]} file(s) not clang-formatted: ${bad[*]}" >&2
  echo "[format] fix with: git ls-files '*.h' '*.cc' | xargs clang-format -i" >&2
  exit 1
fi
echo "[format] ${#files[@]} files clang-formatted"
