#!/usr/bin/env bash
# Configures and builds d2gs in build/ (Release, warnings as errors). The CUDA backend is compiled
# when nvcc is found (D2GS_CUDA=AUTO); pass extra CMake options as arguments.
set -euo pipefail
cd "$(dirname "$0")/.."
generator=()
command -v ninja >/dev/null && generator=(-G Ninja)
if [ ! -f build/CMakeCache.txt ]; then
  cmake -S . -B build "${generator[@]}" -DCMAKE_BUILD_TYPE=Release -DD2GS_WERROR=ON "$@"
elif [ $# -gt 0 ]; then
  cmake -S . -B build "$@"
fi
cmake --build build -j "$(nproc)"
