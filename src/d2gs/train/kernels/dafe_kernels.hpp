#pragma once
// DAFE's loss term (train/losses.cpp: dafe_loss, method.md §5) as kernels, forward and backward, with the
// per-value arithmetic of train/loss_math.hpp (the CPU's). Images are interleaved H x W x C floats, the
// far-region mask H x W bytes (non-zero: far).
//
//  - DafeSumKernel: one thread per value (pixel p = i / C): |a − b| where mask[p] is set, and 1 on the
//    pixel's channel 0 (the masked pixel count); both summed per block in double (block_sum: warp
//    shuffles, then the warps' sums in order) into one partial each per block, no atomics.
//  - DafeTotalKernel: one block adds the partials in a fixed order (thread t: partials t, t + 256, …; then
//    the block's sum), and thread 0 writes the totals: the loss (sum / denominator: the masked pixels for
//    the paper's form, C·H·W for the release's; 0 when it is 0), the gradient's scale g = scale/denominator
//    rounded to float once, and whether there is a gradient at all (denominator ≠ 0).
//  - DafeGradKernel: one thread per value: grad += g·sign(a − b) where the pixel is masked, added to what
//    the buffer holds (the L1 and SSIM gradients in the training step), as the CPU's dafe_loss adds.
//
// The count is an exact integer in double and g is the CPU's expression, so the gradient is the CPU's
// bit for bit; the loss is a double sum of the same float terms in another (fixed) order.
#include <stdint.h>

#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/kernels/block_sum.hpp"
#include "d2gs/train/loss_math.hpp"

namespace d2gs::train_kernels {

struct DafeSumArgs {
  int n = 0;  // W·H·C values
  int channels = 0;
  const float* a = nullptr;     // H x W x C: the (clamped) render
  const float* b = nullptr;     // H x W x C: the ground truth
  const uint8_t* mask = nullptr;  // H x W
  double* partial_sums = nullptr;    // one per block: the block's sum of the masked |a − b|
  double* partial_masked = nullptr;  // one per block: the block's masked pixels
};

struct DafeSumKernel {
  struct Shared {
    BlockSumShared sum, masked;
  };
  template <class Block>
  D2GS_HD static void run(Block& b, Shared& sh, const DafeSumArgs& a) {
    auto s = b.template reg<double>();
    auto m = b.template reg<double>();
    auto other = b.template reg<double>();
    b.threads([&](const Thread& t) {
      const int i = t.global_x();
      s[t] = 0.0;
      m[t] = 0.0;
      if (i >= a.n || !a.mask[i / a.channels]) return;
      s[t] = static_cast<double>(dafe_term(a.a[i], a.b[i]));
      m[t] = i % a.channels == 0 ? 1.0 : 0.0;
    });
    block_sum(b, sh.sum, s, other, [&](const Thread& t, double total) { a.partial_sums[t.block_x] = total; });
    block_sum(b, sh.masked, m, other, [&](const Thread& t, double total) { a.partial_masked[t.block_x] = total; });
  }
};

struct DafeTotals {
  double loss = 0.0;
  float g = 0.0f;  // the gradient's scale: scale / denominator, rounded to float
  int apply = 0;   // the denominator is not 0: the masked values get a gradient
};

struct DafeTotalArgs {
  int blocks = 0;  // partials of DafeSumKernel
  const double* partial_sums = nullptr;
  const double* partial_masked = nullptr;
  double values = 0.0;  // C·H·W (the release's denominator)
  bool paper_form = false;
  float scale = 1.0f;
  DafeTotals* totals = nullptr;
};

// One block.
struct DafeTotalKernel {
  struct Shared {
    BlockSumShared sum, masked;
    double total_sum;
  };
  template <class Block>
  D2GS_HD static void run(Block& b, Shared& sh, const DafeTotalArgs& a) {
    auto s = b.template reg<double>();
    auto m = b.template reg<double>();
    auto other = b.template reg<double>();
    b.threads([&](const Thread& t) {
      double vs = 0.0, vm = 0.0;
      for (int i = t.linear(); i < a.blocks; i += t.block_threads()) {
        vs += a.partial_sums[i];
        vm += a.partial_masked[i];
      }
      s[t] = vs;
      m[t] = vm;
    });
    block_sum(b, sh.sum, s, other, [&](const Thread&, double total) { sh.total_sum = total; });
    block_sum(b, sh.masked, m, other, [&](const Thread&, double masked) {  // thread 0, as the store above
      const double denominator = dafe_denominator(masked, a.values, a.paper_form);
      DafeTotals r;
      if (denominator != 0.0) {
        r.loss = sh.total_sum / denominator;
        r.g = dafe_gradient_scale(a.scale, denominator);
        r.apply = 1;
      }
      *a.totals = r;
    });
  }
};

struct DafeGradArgs {
  int n = 0;  // W·H·C values
  int channels = 0;
  const float* a = nullptr;
  const float* b = nullptr;
  const uint8_t* mask = nullptr;
  const DafeTotals* totals = nullptr;
  float* grad = nullptr;  // H x W x C: += DAFE's gradient
};

D2GS_HD void dafe_grad_thread(int i, const DafeGradArgs& a) {
  if (!a.totals->apply || !a.mask[i / a.channels]) return;
  a.grad[i] += dafe_gradient(a.totals->g, a.a[i], a.b[i]);
}
using DafeGradKernel = render::kernels::PerItemKernel<DafeGradArgs, dafe_grad_thread>;

}  // namespace d2gs::train_kernels
