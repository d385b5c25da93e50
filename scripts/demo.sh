#!/usr/bin/env bash
# Sets up (Debian packages), builds and runs the demo: the built-in synthetic scene, D²GS trained on 3 of
# its views, the held-out views evaluated, an HTML report (its path is the last line printed).
set -euo pipefail
cd "$(dirname "$0")/.."
./scripts/setup.sh
./scripts/build.sh --target d2gs   # the program only; test.sh builds the tests and benchmarks
build/d2gs demo -o demo "$@"
