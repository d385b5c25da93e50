#pragma once
// Fixed-order sums of doubles over a block and over the blocks' partial sums, without atomics: the same
// value on every run, on the GPU and in emulation (used by the SSIM and DAFE kernels).
#include "d2gs/render/kernels/block.hpp"

namespace d2gs::train_kernels {

using render::kernels::kBlockThreads;
using render::kernels::kWarpSize;
using render::kernels::Thread;

// The block's sum of s (one value per thread), handed to store(t, total) on thread 0: warp sums by
// shfl_down, lane 0 of each warp into shared memory, thread 0 adds the warps' sums in order. Every thread
// calls it.
struct BlockSumShared {
  double warp_sums[kBlockThreads / kWarpSize];
};
template <class Block, class Reg, class Store>
D2GS_HD void block_sum(Block& b, BlockSumShared& sh, Reg& s, Reg& other, Store store) {
  for (int offset = kWarpSize / 2; offset > 0; offset /= 2) {
    b.shfl_down(other, s, offset);
    b.threads([&](const Thread& t) { s[t] += other[t]; });
  }
  b.threads([&](const Thread& t) {
    if (t.lane() == 0) sh.warp_sums[t.warp()] = s[t];
  });
  b.sync();
  b.threads([&](const Thread& t) {
    if (t.linear() != 0) return;
    double total = 0.0;
    for (int w = 0; w < t.block_threads() / kWarpSize; ++w) total += sh.warp_sums[w];
    store(t, total);
  });
}

struct SumPartialsArgs {
  int n = 0;
  const double* partials = nullptr;
  double* sum = nullptr;
};

// One block: thread t adds partials t, t + blockDim, … in order, then the block's sum.
struct SumPartialsKernel {
  using Shared = BlockSumShared;
  template <class Block>
  D2GS_HD static void run(Block& b, Shared& sh, const SumPartialsArgs& a) {
    auto s = b.template reg<double>();
    auto other = b.template reg<double>();
    b.threads([&](const Thread& t) {
      double v = 0.0;
      for (int i = t.linear(); i < a.n; i += t.block_threads()) v += a.partials[i];
      s[t] = v;
    });
    block_sum(b, sh, s, other, [&](const Thread&, double total) { *a.sum = total; });
  }
};

}  // namespace d2gs::train_kernels
