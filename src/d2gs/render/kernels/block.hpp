#pragma once
// The shape of every kernel of the CUDA backend, and what a kernel body may ask of its block.
//
// A kernel is a struct with a POD `Shared` (its __shared__ memory) and one body
//
//   template <class Block> D2GS_HD static void run(Block& b, Shared& sh, const Args& args);
//
// written once and compiled twice: by nvcc inside the generic __global__ shell of cuda/device_block.cuh
// (Block = cuda::DeviceBlock: one call per GPU thread), and by the host compiler inside the emulator of
// kernels/emulate.hpp (Block = emulate::HostBlock: one call per block, looping over the block's threads).
// The body speaks to its block only through these members, so both paths run the same statements:
//
//   b.threads(f)          one phase: f(const Thread&) for every thread of the block. On the GPU, f runs
//                         once, for the calling thread; in emulation, once per thread, in order.
//   b.sync()              __syncthreads(): where one phase hands shared memory to the next. Values that
//                         live across phases are kept in registers (below) or shared memory, never in
//                         locals of f.
//   b.reg<T>()            a per-thread register (r[t] inside f). On the GPU one T; in emulation one T per
//                         thread of the block, poisoned (NaN / 0xa5 bytes) like uninitialised registers.
//   b.shfl_up/down/xor(dst, src, k)
//                         a warp shuffle (__shfl_*_sync over the full warp) called by every thread, outside
//                         f: dst[t] = src[source lane], in emulation by CUDA's definition of the source lane.
//                         A struct register is shuffled one 32-bit word at a time on the GPU.
//   b.warp_any(dst, src)  __any_sync: dst[t] = 1 where some lane of t's warp has src != 0 (outside f).
//   b.shfl_down_if(active, dst, src, k)
//                         shfl_down taken only by the warps where the warp-uniform `active` (a warp_any
//                         result) is set, as `if (active) dst = __shfl_down_sync(...)`; the emulator
//                         rejects an `active` that differs within a warp.
//   b.atomic_add(p, v)    atomicAdd inside f; in emulation a plain add in thread order.
//   b.sync_count(r)       __syncthreads_count(r[t] != 0), called by every thread outside f: a barrier that
//                         returns to all threads how many of them hold a non-zero register.
//   b.block_idx()         blockIdx, outside f too (loop bounds that are the same for the whole block).
//
// Thread indices follow CUDA: x fastest, lane = linear index % 32. Per-thread math lives in D2GS_HD
// functions (projection_math.hpp, sh_math.hpp, raster_math.hpp) shared with the CPU reference backend.
#include <stdint.h>
#include <string.h>

#include "d2gs/core/host_device.hpp"

namespace d2gs::render::kernels {

inline constexpr int kWarpSize = 32;

struct Dim {
  int x = 1, y = 1;
};

struct Thread {
  int x = 0, y = 0;              // threadIdx
  int block_x = 0, block_y = 0;  // blockIdx
  int dim_x = 1, dim_y = 1;      // blockDim
  D2GS_HD int linear() const { return y * dim_x + x; }
  D2GS_HD int lane() const { return linear() % kWarpSize; }
  D2GS_HD int warp() const { return linear() / kWarpSize; }
  D2GS_HD int block_threads() const { return dim_x * dim_y; }
  D2GS_HD int global_x() const { return block_x * dim_x + x; }  // 1-D grids: the item of this thread
};

// The launch geometry of a 1-D kernel over n items.
inline constexpr int kBlockThreads = 256;
D2GS_HD int blocks_for(long long n, int block = kBlockThreads) {
  return static_cast<int>((n + block - 1) / block);
}

// Host side: launches Body over n items on `backend` (render/kernels/pipeline.hpp's backends), one
// thread per item in blocks of kBlockThreads.
template <class Body, class Backend, class Args>
void launch_per_item(Backend& backend, long long n, const Args& args) {
  backend.template launch<Body>(blocks_for(n), kBlockThreads, args);
}

// The commonest kernel: one thread per item, no shared memory, one phase; thread i < args.n runs
// Item(i, args). Projection, SH, tile counts, key emission and Adam are this.
template <class Args, void (*Item)(int, const Args&)>
struct PerItemKernel {
  struct Shared {};
  template <class Block>
  D2GS_HD static void run(Block& b, Shared&, const Args& a) {
    b.threads([&](const Thread& t) {
      const int i = t.global_x();
      if (i < a.n) Item(i, a);
    });
  }
};

// The IEEE bits of a float (the sort keys order positive depths by these bits).
D2GS_HD uint32_t float_bits(float v) {
#if defined(__CUDA_ARCH__)
  return __float_as_uint(v);
#else
  uint32_t bits;
  memcpy(&bits, &v, sizeof bits);
  return bits;
#endif
}

}  // namespace d2gs::render::kernels
