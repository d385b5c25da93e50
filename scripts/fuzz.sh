#!/usr/bin/env bash
# Builds the libFuzzer targets of fuzz/ (clang, ASan + UBSan, in build-fuzz/) and runs each for SECONDS
# (default 60), one target at a time, from its committed seed corpus fuzz/corpus/<target>/.
#   scripts/fuzz.sh [SECONDS] [TARGET...]      e.g. scripts/fuzz.sh 600 fuzz_image
# Every target of fuzz/ runs unless targets are named. Inputs that reach new code are kept in
# build-fuzz/corpus/<target>/ (not committed; later runs start from them too), crashing inputs in
# build-fuzz/findings/<target>/ (emptied at the start of each run). Prints one line per target (executions, coverage, findings) and exits
# non-zero when a target found a crash, a leak or a timeout. CI (scripts/test.sh) runs it for a few
# seconds per target. Needs clang and libclang-rt-dev (scripts/setup.sh installs them).
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=60
if [ $# -gt 0 ]; then
  [[ "$1" =~ ^[0-9]+$ ]] || { echo "fuzz.sh: SECONDS must be a whole number, got '$1'" >&2; exit 2; }
  seconds=$1
  shift
fi
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
  for f in fuzz/fuzz_*.cpp; do targets+=("$(basename "$f" .cpp)"); done
fi
for t in "${targets[@]}"; do
  [ -f "fuzz/$t.cpp" ] || { echo "fuzz.sh: no target '$t' (fuzz/$t.cpp)" >&2; exit 2; }
  [ -d "fuzz/corpus/$t" ] || { echo "fuzz.sh: target '$t' has no seed corpus (fuzz/corpus/$t/)" >&2; exit 2; }
done
command -v clang++ >/dev/null || { echo "fuzz.sh: clang++ not found (run scripts/setup.sh)" >&2; exit 2; }

if [ ! -f build-fuzz/CMakeCache.txt ]; then
  generator=()
  command -v ninja >/dev/null && generator=(-G Ninja)
  launcher=()
  command -v ccache >/dev/null && launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  CC=clang CXX=clang++ cmake -S . -B build-fuzz "${generator[@]}" "${launcher[@]}" -DCMAKE_BUILD_TYPE=Release \
    -DD2GS_BUILD_FUZZERS=ON -DD2GS_BUILD_TESTS=OFF -DD2GS_BUILD_BENCHMARKS=OFF -DD2GS_CUDA=OFF -DD2GS_WERROR=ON \
    >/dev/null
fi
cmake --build build-fuzz -j "$(nproc)" --target "${targets[@]}"

# OpenCV (not instrumented) would allocate whatever an image header claims: cap it well below the
# fuzzer's memory limit so that a huge claimed size is refused, as a real file that size would be slow.
# 1 M pixels: a 34-byte input that decodes to 513 x 5121 took 1.3 s per run through the instrumented
# checks on a loaded machine; smaller claims keep every unit far from the 10 s timeout.
export OPENCV_IO_MAX_IMAGE_PIXELS=1000000
status=0
for t in "${targets[@]}"; do
  corpus=build-fuzz/corpus/$t
  findings=build-fuzz/findings/$t
  rm -rf "$findings"
  mkdir -p "$corpus" "$findings"
  log=build-fuzz/$t.log
  started=$SECONDS
  set +e
  "build-fuzz/fuzz/$t" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$findings/" "$corpus" "fuzz/corpus/$t" >"$log" 2>&1
  rc=$?
  set -e
  elapsed=$((SECONDS - started))
  # (a log without these lines, from a target that stopped at once, must not end the script: || true)
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1 || true)
  cov=$(grep -o 'cov: [0-9]*' "$log" | tail -1 | cut -d' ' -f2 || true)
  ft=$(grep -o 'ft: [0-9]*' "$log" | tail -1 | cut -d' ' -f2 || true)
  found=$(find "$findings" -type f | wc -l)
  line="$t: ${runs:-?} executions in ${elapsed} s, cov ${cov:-?}, ft ${ft:-?}, corpus $(find "$corpus" -type f | wc -l) files, findings $found"
  if [ "$rc" -ne 0 ]; then
    status=1
    line+=" — FAILED (exit $rc; log $log)"
    grep -m 3 -E 'ERROR: |runtime error|deadly signal' "$log" >&2 || true
  fi
  echo "$line"
done
if [ "$status" -ne 0 ]; then
  echo "fuzz.sh: a target failed; reproduce with build-fuzz/fuzz/TARGET FILE from build-fuzz/findings/TARGET/" >&2
fi
exit "$status"
