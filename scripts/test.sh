#!/usr/bin/env bash
# Sets up (Debian packages), builds, runs every fuzz target for a few seconds (ASan + UBSan, from the
# committed seed corpora; scripts/fuzz.sh) and then every test. This is what CI runs (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
./scripts/build.sh
./scripts/fuzz.sh 3
ctest --test-dir build --output-on-failure -j "$(nproc)"
