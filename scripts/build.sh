#!/usr/bin/env bash
# Configures and builds d2gs in build/ (Release, warnings as errors). The CUDA backend is compiled
# when nvcc is found (D2GS_CUDA=AUTO). `--target NAME` (first argument) builds only that target, e.g.
# `--target d2gs` for the program without tests and benchmarks; other arguments are CMake options.
set -euo pipefail
cd "$(dirname "$0")/.."
target=()
if [ "${1:-}" = "--target" ]; then
  [ $# -ge 2 ] || { echo "build.sh: --target needs a target name" >&2; exit 2; }
  target=(--target "$2")
  shift 2
fi
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
if [ ! -f build/CMakeCache.txt ]; then
  cmake -S . -B build "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DD2GS_WERROR=ON "$@"
elif [ $# -gt 0 ]; then
  cmake -S . -B build "$@"
fi
cmake --build build -j "$(nproc)" "${target[@]}"
