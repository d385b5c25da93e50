#!/usr/bin/env bash
# Installs every build and test dependency of d2gs from Debian packages. Idempotent: packages already
# present are left alone, and nothing is downloaded from anywhere but the Debian archive. chromium (about
# 45 s and 350 MB with its dependencies) lets the report tests load the HTML reports in a real browser;
# clang with its sanitizer and libFuzzer runtimes (libclang-rt-dev) builds the fuzz targets (scripts/fuzz.sh).
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config
  libglm-dev libnanoflann-dev nlohmann-json3-dev libcli11-dev libspdlog-dev libfmt-dev
  libomp-dev libopenblas-dev libjpeg-dev
  libopencv-core-dev libopencv-imgproc-dev libopencv-imgcodecs-dev
  libopencv-features2d-dev libopencv-calib3d-dev libopencv-dnn-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  python3 python3-numpy
  clang libclang-rt-dev
  chromium
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done

if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  SUDO=""
  if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
  export DEBIAN_FRONTEND=noninteractive
  $SUDO apt-get update -qq
  $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
else
  echo "setup: all dependencies present"
fi
