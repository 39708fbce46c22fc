#!/usr/bin/env bash
# Installs exactly the Debian 12 packages MGSR-CPU needs. Idempotent: when every package is already
# installed it returns at once without touching apt.
set -euo pipefail

PACKAGES=(
  # toolchain
  g++ make cmake pkg-config
  # libraries (only the OpenCV modules we use, not the whole of libopencv-dev)
  libeigen3-dev libceres-dev libgoogle-glog-dev libgflags-dev
  libopencv-core-dev libopencv-imgproc-dev libopencv-imgcodecs-dev
  libopen3d-dev libnanoflann-dev nlohmann-json3-dev
  # .spz export (gzip)
  zlib1g-dev
  # data-parallel training under mpirun (-DMGSR_WITH_MPI=ON, scripts/build.sh)
  libopenmpi-dev openmpi-bin
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
  # real COLMAP, for interoperability tests and the photo pipeline
  colmap
  # charts of the benchmark harness (mgsr_bench)
  gnuplot-nox
  # the formatting check of CI (scripts/check_format.sh)
  clang-format
)

missing=()
for p in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "[install_deps] all ${#PACKAGES[@]} packages present"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "[install_deps] installing ${#missing[@]} package(s): ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "[install_deps] done"
