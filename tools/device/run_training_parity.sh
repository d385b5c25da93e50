#!/bin/bash
# Training parity of the GPU rasterizer against the CPU backend (issue 27), on the device machine, from the
# pack of tools/device/pack.sh: fern, 3 views, 504x378, the published cloud, ITERS iterations (1 000), one
# line per run with the test PSNR (mean and per view), the Gaussians and the training seconds.
#   CASES   "method:seed:device[:isa]" items, run in order (isa sets D2GS_CPU_ISA for a CPU run)
#   THREADS OpenMP threads (16)
# D²GS runs use the release preset with fern's values (--scene-preset fern), as the earlier parity rows.
set -u
source "$(dirname "$0")/unpack.sh"
psnr() {  # results.json -> "mean (v0 / v8 / v16)"
  tr -d ' \n' < "$1" | grep -o '"PSNR":[-0-9.e]*' | cut -d: -f2 |
    awk 'NR==1{m=$1} NR>1{v=v (v==""?"":" / ") sprintf("%.2f",$1)} END{printf "%.3f (%s)", m, v}'
}
echo "method seed device isa | PSNR (views) | Gaussians | train s"
for c in ${CASES:-d2gs:0:cuda}; do
  IFS=: read -r method seed device isa <<< "$c"
  extra=()
  [ "$method" = d2gs ] && extra=(--scene-preset fern)
  run=/tmp/parity_${method}_${seed}_${device}_${isa:-native}_$RANDOM
  env ${isa:+D2GS_CPU_ISA=$isa} OMP_NUM_THREADS=${THREADS:-16} $P/bin/d2gs train -s $data/nerf_llff_data/fern -m $run \
    -r 8 --n-views 3 --method "$method" "${extra[@]}" --init $data/published_init/fern/3_views_fused.ply \
    --iterations ${ITERS:-1000} --seed "$seed" --device "$device" --quiet > $run.log 2>&1 || { echo "$c failed: $(tail -1 $run.log)"; continue; }
  g=$(tr -d ' \n' < $run/results.json | grep -o '"gaussians":[0-9]*' | cut -d: -f2)
  s=$(tr -d ' \n' < $run/results.json | grep -o '"train_seconds":[0-9.]*' | cut -d: -f2)
  echo "$method $seed $device ${isa:-native} | $(psnr $run/results.json) | $g | $s"
done
