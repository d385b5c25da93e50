#!/usr/bin/env bash
# Sets up (Debian packages), builds and runs the main job on the built-in synthetic demo scene.
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
./scripts/build.sh
build/d2gs demo -o demo "$@"
build/d2gs info -s demo --n-views 3
