#!/usr/bin/env bash
# Packs what the GPU checks need into .devpack/ (ignored by git) for the `device` tool of this workplace.
# The GPU machine has nvcc and the CUDA runtime but none of our Debian libraries, and the tool carries at
# most 64 MiB. The pack holds:
# - the stripped test and benchmark programs and d2gs built here (build/, for sm_90), as one xz archive;
# - the shared libraries they load, except glibc's, libstdc++, libgcc_s, libz and the CUDA runtime,
#   as one xz archive (about 50 MB);
# - the part of fern that the GPU tests read.
# Then: run(command="bash tools/device/run_gpu_checks.sh", carry=[".devpack"]).
set -euo pipefail
cd "$(dirname "$0")/../.."
grep -qx '/.devpack/' .git/info/exclude 2>/dev/null || echo '/.devpack/' >> .git/info/exclude
programs=(build/tests/cuda/test_cuda build/bench/bench_cuda build/bench/bench_render build/bench/bench_train build/d2gs)
for p in "${programs[@]}"; do [ -x "$p" ] || { echo "pack: $p is missing: build first (scripts/build.sh)" >&2; exit 1; }; done
rm -rf .devpack && mkdir -p .devpack/shared/data/nerf_llff_data/fern .devpack/shared/data/published_init
bins=$(mktemp -d)
mkdir "$bins/bin" && cp "${programs[@]}" "$bins/bin/" && strip "$bins"/bin/*
tar cf - -C "$bins" bin | xz -9e -T2 > .devpack/devbin.tar.xz  # about 2.4 MB instead of 13 MB
rm -rf "$bins"
fern=../shared/data/nerf_llff_data/fern
cp -r "$fern/images_8" "$fern/sparse" "$fern/poses_bounds.npy" .devpack/shared/data/nerf_llff_data/fern/
cp -r ../shared/data/published_init/fern .devpack/shared/data/published_init/
libs=$(mktemp -d)
mkdir "$libs/devlib"
ldd "${programs[@]}" | awk '/=>/ {print $3}' | sort -u |
  grep -v -E '/(libc|libm|libdl|libpthread|librt|libstdc\+\+|libgcc_s|libz|libresolv|libcudart)\.so' |
  while read -r lib; do cp -L "$lib" "$libs/devlib/"; done
strip --strip-unneeded "$libs"/devlib/* 2>/dev/null || true
tar cf - -C "$libs" devlib | xz -9e -T2 > .devpack/devlib.tar.xz
rm -rf "$libs"
size=$(( $(du -sb .devpack | cut -f1) + $(git ls-files -z | xargs -0 du -cb | tail -1 | cut -f1) ))
echo "pack: .devpack ready; with the tracked files, $((size / 1048576)) MiB travel (limit 64 MiB)"
