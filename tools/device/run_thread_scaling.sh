#!/bin/bash
# Thread scaling of the CPU backend on the device machine's cores (issue 26), from the pack of
# tools/device/pack.sh, after run_gpu_checks.sh has unpacked it (or alone: it unpacks what is missing).
# For each thread count: the rasterizer's forward + backward at 100k Gaussians (bench_render), and a
# 300-iteration fern D²GS training from the published cloud (d2gs train, wall time of the command).
# THREADS overrides the list; ITERS the training length.
set -u
source "$(dirname "$0")/unpack.sh"
lscpu | grep -E "Model name|^CPU\(s\)|Thread|Flags" | cut -c1-120
for th in ${THREADS:-1 2 4 8 16}; do
  echo "== $th threads"
  OMP_NUM_THREADS=$th $P/bin/bench_render --benchmark_filter='BM_RenderForwardBackward/100000' \
    --benchmark_min_time=1 --benchmark_repetitions=3 --benchmark_report_aggregates_only=true 2>&1 | grep -E "mean|stddev"
  rm -rf /tmp/ts_run
  start=$(date +%s.%N)
  OMP_NUM_THREADS=$th $P/bin/d2gs train -s $data/nerf_llff_data/fern -m /tmp/ts_run -r 8 --n-views 3 --method d2gs \
    --scene-preset fern --init $data/published_init/fern/3_views_fused.ply --iterations ${ITERS:-300} --seed 0 \
    --device cpu --quiet > /tmp/ts_log 2>&1 || tail -3 /tmp/ts_log
  end=$(date +%s.%N)
  echo "train ${ITERS:-300} its: $(awk "BEGIN{print $end - $start}") s wall; $(grep -o "\"train_seconds\": *[0-9.]*" /tmp/ts_run/results.json)"
done
