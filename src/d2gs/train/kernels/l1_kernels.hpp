#pragma once
// The L1 loss and its gradient (train/losses.cpp: l1_loss), one thread per value: grad += scale/count *
// loss_sign(a - b) (train/loss_math.hpp), and the sum of |a - b| reduced in the block (warp shuffles, then
// the warp sums in shared memory) and added to the total with one atomic per block. The gradient is the
// CPU's bit for bit; the sum is in another order (and on the GPU the blocks' atomics in no fixed order),
// equal to rounding.
#include <math.h>

#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/loss_math.hpp"

namespace d2gs::train_kernels {

using render::kernels::kBlockThreads;
using render::kernels::kWarpSize;
using render::kernels::Thread;

struct L1Args {
  int n = 0;
  const float* a = nullptr;
  const float* b = nullptr;
  float* grad = nullptr;  // null: the value only
  float g = 0;            // scale / count
  double* sum = nullptr;  // += sum of |a - b|
};

struct L1Kernel {
  struct Shared {
    double warp_sums[kBlockThreads / kWarpSize];
  };
  template <class Block>
  D2GS_HD static void run(Block& b, Shared& sh, const L1Args& a) {
    auto s = b.template reg<double>();
    auto other = b.template reg<double>();
    b.threads([&](const Thread& t) {
      const int i = t.global_x();
      s[t] = 0.0;
      if (i >= a.n) return;
      const float d = a.a[i] - a.b[i];
      s[t] = fabsf(d);
      if (a.grad) a.grad[i] += a.g * loss_sign(d);
    });
    for (int offset = kWarpSize / 2; offset > 0; offset /= 2) {  // warp sum: lane 0 ends with the total
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
      b.atomic_add(a.sum, total);
    });
  }
};

}  // namespace d2gs::train_kernels
