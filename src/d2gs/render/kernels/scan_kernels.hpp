#pragma once
// Inclusive prefix sum of int32 values, in place (tiles per Gaussian -> intersection offsets).
// BlockScanKernel scans each block's slice: a warp-level scan by shuffles, the warp totals through
// shared memory (scanned by warp 0 with the same shuffles), then each thread adds the totals of the
// warps before it; the block's total goes to block_sums. The host scans block_sums the same way
// (recursively) and AddBlockOffsetsKernel adds to every block the totals of the blocks before it
// (kernels/pipeline.hpp: inclusive_scan). Integer sums: results are exact on both paths.
#include "d2gs/render/kernels/block.hpp"

namespace d2gs::render::kernels {

inline constexpr int kScanBlock = 256;  // threads per block, one value per thread

struct ScanArgs {
  int n = 0;
  int* data = nullptr;        // n values, scanned in place within each block
  int* block_sums = nullptr;  // one per block: the block's total
};

struct BlockScanKernel {
  struct Shared {
    int warp_totals[kScanBlock / kWarpSize];
    int warp_prefix[kScanBlock / kWarpSize];  // inclusive scan of warp_totals
  };
  template <class Block>
  D2GS_HD static void run(Block& b, Shared& sh, const ScanArgs& a) {
    auto v = b.template reg<int>();
    auto up = b.template reg<int>();
    b.threads([&](const Thread& t) {
      const int i = t.global_x();
      v[t] = i < a.n ? a.data[i] : 0;
    });
    for (int d = 1; d < kWarpSize; d *= 2) {  // warp inclusive scan (Hillis-Steele by shuffles)
      b.shfl_up(up, v, d);
      b.threads([&](const Thread& t) {
        if (t.lane() >= d) v[t] += up[t];
      });
    }
    b.threads([&](const Thread& t) {
      if (t.lane() == kWarpSize - 1) sh.warp_totals[t.warp()] = v[t];
    });
    b.sync();
    auto w = b.template reg<int>();  // warp 0 scans the warp totals
    b.threads([&](const Thread& t) {
      const int warps = t.block_threads() / kWarpSize;
      w[t] = t.linear() < warps ? sh.warp_totals[t.linear()] : 0;
    });
    for (int d = 1; d < kWarpSize; d *= 2) {
      b.shfl_up(up, w, d);
      b.threads([&](const Thread& t) {
        if (t.lane() >= d) w[t] += up[t];
      });
    }
    b.threads([&](const Thread& t) {
      if (t.linear() < t.block_threads() / kWarpSize) sh.warp_prefix[t.linear()] = w[t];
    });
    b.sync();
    b.threads([&](const Thread& t) {
      const int total = v[t] + (t.warp() > 0 ? sh.warp_prefix[t.warp() - 1] : 0);
      const int i = t.global_x();
      if (i < a.n) a.data[i] = total;
      if (t.linear() == t.block_threads() - 1) a.block_sums[t.block_x] = total;
    });
  }
};

struct AddBlockOffsetsArgs {
  int n = 0;
  int* data = nullptr;
  const int* scanned_block_sums = nullptr;  // inclusive scan of the block totals
};

struct AddBlockOffsetsKernel {
  struct Shared {};
  template <class Block>
  D2GS_HD static void run(Block& b, Shared&, const AddBlockOffsetsArgs& a) {
    b.threads([&](const Thread& t) {
      const int i = t.global_x();
      if (i < a.n && t.block_x > 0) a.data[i] += a.scanned_block_sums[t.block_x - 1];
    });
  }
};

}  // namespace d2gs::render::kernels
