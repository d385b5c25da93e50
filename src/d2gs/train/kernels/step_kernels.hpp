#pragma once
// The small per-value kernels that join the stages of a device-resident training step
// (resident_step.hpp), each the trainer's own loop (train/trainer.cpp) one thread per value:
//  * ClampKernel: the losses' input, the render clamped to [0, 1] (loss_math.hpp's clamp_unit), and the
//    image gradient zeroed for the losses to add to.
//  * ClampGradientKernel: no gradient where the clamp changed the value (clamp_blocks_gradient).
//  * Mean2dNdcKernel: compositing's pixel-space d loss / d mean2d times (W/2, H/2), the CPU backend's
//    convention for the densification statistic (render/kernels/kernel_rasterizer.cpp does the same on the
//    host).
//  * ZeroCountKernel: the zeros of the opacity multiplier per block (block_sum.hpp, no atomics), for the
//    log's drop fraction; SumPartialsKernel adds the blocks'.
//  * NonFiniteKernel: sets *flag when a value is NaN or infinite (every writer writes the same 1: the
//    race is benign), the trainer's all_finite guard as one scalar to read back.
#include <math.h>

#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/kernels/block_sum.hpp"
#include "d2gs/train/loss_math.hpp"

namespace d2gs::train_kernels {

struct ClampArgs {
  int n = 0;
  const float* rgb = nullptr;
  float* clamped = nullptr;
  float* grad = nullptr;  // zeroed
};

D2GS_HD void clamp_thread(int i, const ClampArgs& a) {
  a.clamped[i] = clamp_unit(a.rgb[i]);
  a.grad[i] = 0.0f;
}
using ClampKernel = render::kernels::PerItemKernel<ClampArgs, clamp_thread>;

struct ClampGradientArgs {
  int n = 0;
  const float* rgb = nullptr;
  float* grad = nullptr;
};

D2GS_HD void clamp_gradient_thread(int i, const ClampGradientArgs& a) {
  if (clamp_blocks_gradient(a.rgb[i])) a.grad[i] = 0.0f;
}
using ClampGradientKernel = render::kernels::PerItemKernel<ClampGradientArgs, clamp_gradient_thread>;

struct Mean2dNdcArgs {
  int n = 0;  // Gaussians
  const float* d_mean2d = nullptr;  // n x 2, pixels
  float sx = 0, sy = 0;             // W/2, H/2
  float* out = nullptr;             // n x 2
};

D2GS_HD void mean2d_ndc_thread(int i, const Mean2dNdcArgs& a) {
  a.out[2 * i] = a.d_mean2d[2 * i] * a.sx;
  a.out[2 * i + 1] = a.d_mean2d[2 * i + 1] * a.sy;
}
using Mean2dNdcKernel = render::kernels::PerItemKernel<Mean2dNdcArgs, mean2d_ndc_thread>;

struct ZeroCountArgs {
  int n = 0;
  const float* values = nullptr;
  double* partials = nullptr;  // one per block
};

struct ZeroCountKernel {
  using Shared = BlockSumShared;
  template <class Block>
  D2GS_HD static void run(Block& b, Shared& sh, const ZeroCountArgs& a) {
    auto s = b.template reg<double>();
    auto other = b.template reg<double>();
    b.threads([&](const Thread& t) {
      const int i = t.global_x();
      s[t] = i < a.n && a.values[i] == 0.0f ? 1.0 : 0.0;
    });
    block_sum(b, sh, s, other, [&](const Thread& t, double total) { a.partials[t.block_x] = total; });
  }
};

struct NonFiniteArgs {
  int n = 0;
  const float* values = nullptr;
  int* flag = nullptr;
};

D2GS_HD void non_finite_thread(int i, const NonFiniteArgs& a) {
  if (!isfinite(a.values[i])) *a.flag = 1;
}
using NonFiniteKernel = render::kernels::PerItemKernel<NonFiniteArgs, non_finite_thread>;

}  // namespace d2gs::train_kernels
