#!/bin/bash
# The GPU checks on the device machine (issue 27), from the pack of tools/device/pack.sh: every GPU test,
# the CUDA rasterizer benchmark, and compute-sanitizer racecheck and memcheck on a few of the tests.
set -u
R=$PWD; P=$R/.devpack
tar xJf $P/devlib.tar.xz -C /tmp && tar xJf $P/devbin.tar.xz -C $P && export LD_LIBRARY_PATH=/tmp/devlib:/usr/local/cuda/lib64:/usr/local/cuda/targets/x86_64-linux/lib
echo "repo at $R"
mkdir -p /work 2>/dev/null
[ -e /work/main ] || ln -s "$R" /work/main
[ -e "$R/../shared" ] || ln -s "$P/shared" "$R/../shared"
ls /work/main/../shared/data/nerf_llff_data/fern >/dev/null || echo "fern not reachable"
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv
nproc
chmod +x $P/bin/*
cd $P/bin
ldd ./test_cuda | grep -i "not found"
echo "== GPU tests"
timeout ${T1:-240} ./test_cuda --gtest_filter='CudaDevice.*:Device*.*:ResidentStep.Device*' 2>&1 | tee $OUT/test_cuda.log | grep -v "^\[ *RUN\|^\[ *OK" | tail -120
if [ "${BENCH:-1}" = 1 ]; then
echo "== bench"
timeout ${T2:-150} ./bench_cuda --benchmark_min_time=1 --benchmark_repetitions=3 --benchmark_report_aggregates_only=false --benchmark_format=console 2>&1 | tee $OUT/bench_cuda.log | tail -30
fi
if [ -x ./d2gs ]; then ./d2gs info 2>&1 | tail -15; fi
if [ "${SAN:-1}" = 1 ] && command -v compute-sanitizer >/dev/null; then
  echo "== racecheck (scan, compositing)"
  timeout ${T3:-120} compute-sanitizer --tool racecheck --print-limit 20 ./test_cuda --gtest_filter='DeviceKernels.InclusiveScan*:DeviceComposite.*' 2>&1 | tail -25
  echo "== memcheck"
  timeout ${T3:-120} compute-sanitizer --tool memcheck --print-limit 20 ./test_cuda --gtest_filter='DeviceKernels.RandomScenes*:DeviceKernels.Ssim*:DeviceKernels.L1*' 2>&1 | tail -25
fi
