#pragma once
// SSIM (eval/ssim.cpp) as kernels: the loss term λ·(1 − mean SSIM) of the training step, forward and
// backward, on images of P planes of W x H floats (planar: plane q at q·W·H).
//
//  - SsimPlanesKernel: one thread per value of the interleaved H x W x C prediction a: writes its planes a,
//    a² and a·b (b: the reference's planar ground truth), the three inputs of the blurs; the reference's
//    own b and b² the same way (SsimReferencePlanesKernel).
//  - BlurRowsKernel, BlurColumnsKernel: the separable 11-tap Gaussian window, one thread per output
//    value, zero padding ("same" size): out = Σ_k w[k]·in[x + k − 5] over the taps inside the image, in k
//    order from 0, each tap one fmaf. That is what the CPU's blur computes on x86-64-v3/v4 (its
//    D2GS_VECTOR_CLONES are compiled with FMA, and GCC contracts acc += w·s into fma(w, s, acc)); on an
//    x86-64 without FMA the CPU rounds the product first (a difference of float rounding, tests/cuda).
//    One thread per output value reading global memory, not shared-memory tiles: the 11 reads of a thread
//    are neighbours of its warp's, served by L1, images are small (fern at 1/8: 504 x 378 x 9 planes), and
//    the row and column passes stay separate kernels as the CPU's passes (fusing them through a
//    shared-memory tile with a 5-pixel apron saves the intermediate's round trip; later, if it shows).
//  - SsimMapKernel: one thread per (channel, pixel): ssim_pixel of eval/ssim_math.hpp (the CPU's
//    arithmetic), the map's local derivatives times g for the backward blurs, and the map's sum per block
//    (double: warp shuffles, then the warps' sums in shared memory) into partials[block], no atomics.
//  - SumPartialsKernel (block_sum.hpp): one block adds the partials in a fixed order (thread t: partials
//    t, t + 256, …; then the same block reduction), so the mean is the same on every run and on the GPU.
//  - SsimGradKernel: one thread per value: grad += ssim_input_gradient of the blurred derivatives (added
//    to what the buffer holds, the L1 gradient in the training step, as the CPU's Ssim::evaluate adds).
#include <math.h>

#include "d2gs/eval/ssim_math.hpp"
#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/kernels/block_sum.hpp"

namespace d2gs::train_kernels {

using render::kernels::kBlockThreads;
using render::kernels::kWarpSize;
using render::kernels::Thread;

inline constexpr int kSsimRadius = kSsimWindow / 2;

// One tap of the blur: acc + w·v with one rounding (fmaf is correctly rounded on the GPU and in glibc).
D2GS_HD float ssim_blur_tap(float acc, float w, float v) { return fmaf(w, v, acc); }

struct SsimPlanesArgs {
  int n = 0;       // W·H·C values of a
  int pixels = 0;  // W·H
  int channels = 0;
  const float* a = nullptr;  // H x W x C, interleaved
  const float* b = nullptr;  // C planes (the reference's ground truth)
  float* planes = nullptr;   // 3·C planes: a (C), a² (C), a·b (C)
};

// Value j = p·C + c of a → planes c, C + c, 2C + c at pixel p.
D2GS_HD void ssim_planes_thread(int j, const SsimPlanesArgs& a) {
  const int p = j / a.channels, c = j % a.channels;
  const long long plane = a.pixels;
  const float v = a.a[j];
  const long long at = c * plane + p;
  a.planes[at] = v;
  a.planes[a.channels * plane + at] = v * v;
  a.planes[2 * a.channels * plane + at] = v * a.b[at];
}
using SsimPlanesKernel = render::kernels::PerItemKernel<SsimPlanesArgs, ssim_planes_thread>;

struct SsimReferencePlanesArgs {
  int n = 0;
  int pixels = 0;
  int channels = 0;
  const float* b = nullptr;  // H x W x C, interleaved
  float* planes = nullptr;   // 2·C planes: b (C), b² (C)
};

D2GS_HD void ssim_reference_planes_thread(int j, const SsimReferencePlanesArgs& a) {
  const int p = j / a.channels, c = j % a.channels;
  const long long plane = a.pixels;
  const float v = a.b[j];
  const long long at = c * plane + p;
  a.planes[at] = v;
  a.planes[a.channels * plane + at] = v * v;
}
using SsimReferencePlanesKernel = render::kernels::PerItemKernel<SsimReferencePlanesArgs, ssim_reference_planes_thread>;

struct BlurArgs {
  int n = 0;  // planes · W · H outputs
  int width = 0, height = 0;
  const float* in = nullptr;
  float* out = nullptr;
  float w[kSsimWindow] = {};
};

// Horizontal pass: output i = (plane, y, x).
D2GS_HD void blur_rows_thread(int i, const BlurArgs& a) {
  const int x = i % a.width;
  const float* row = a.in + (i - x);
  float acc = 0.0f;
  for (int k = 0; k < kSsimWindow; ++k) {
    const int xx = x + k - kSsimRadius;
    if (xx >= 0 && xx < a.width) acc = ssim_blur_tap(acc, a.w[k], row[xx]);
  }
  a.out[i] = acc;
}
using BlurRowsKernel = render::kernels::PerItemKernel<BlurArgs, blur_rows_thread>;

// Vertical pass: output i = (plane, y, x).
D2GS_HD void blur_columns_thread(int i, const BlurArgs& a) {
  const int plane = a.width * a.height;
  const int q = i / plane, yx = i % plane, y = yx / a.width, x = yx % a.width;
  const float* column = a.in + static_cast<long long>(q) * plane + x;
  float acc = 0.0f;
  for (int k = 0; k < kSsimWindow; ++k) {
    const int yy = y + k - kSsimRadius;
    if (yy >= 0 && yy < a.height) acc = ssim_blur_tap(acc, a.w[k], column[static_cast<long long>(yy) * a.width]);
  }
  a.out[i] = acc;
}
using BlurColumnsKernel = render::kernels::PerItemKernel<BlurArgs, blur_columns_thread>;

struct SsimMapArgs {
  int n = 0;  // C·W·H
  const float* mu_a = nullptr;  // C planes each
  const float* s_aa = nullptr;
  const float* s_ab = nullptr;
  const float* mu_b = nullptr;
  const float* s_bb = nullptr;
  float c1 = 0, c2 = 0;
  float g = 0;              // grad_scale / (C·W·H), rounded to float as the CPU's
  float* d_mu = nullptr;    // C planes each; null: the value only
  float* d_saa = nullptr;
  float* d_sab = nullptr;
  double* partials = nullptr;  // one per block: the block's sum of the map
};

struct SsimMapKernel {
  using Shared = BlockSumShared;
  template <class Block>
  D2GS_HD static void run(Block& b, Shared& sh, const SsimMapArgs& a) {
    auto s = b.template reg<double>();
    auto other = b.template reg<double>();
    b.threads([&](const Thread& t) {
      const int i = t.global_x();
      s[t] = 0.0;
      if (i >= a.n) return;
      float m;
      if (a.d_mu)
        m = ssim_pixel<float, true>(a.mu_a[i], a.mu_b[i], a.s_aa[i], a.s_bb[i], a.s_ab[i], a.c1, a.c2, a.g, &a.d_mu[i],
                                    &a.d_saa[i], &a.d_sab[i]);
      else
        m = ssim_pixel<float, false>(a.mu_a[i], a.mu_b[i], a.s_aa[i], a.s_bb[i], a.s_ab[i], a.c1, a.c2, a.g, nullptr,
                                     nullptr, nullptr);
      s[t] = static_cast<double>(m);
    });
    block_sum(b, sh, s, other, [&](const Thread& t, double total) { a.partials[t.block_x] = total; });
  }
};

struct SsimGradArgs {
  int n = 0;  // W·H·C values
  int pixels = 0;
  int channels = 0;
  const float* a = nullptr;              // H x W x C
  const float* b = nullptr;              // C planes
  const float* blurred_d_mu = nullptr;   // C planes each
  const float* blurred_d_saa = nullptr;
  const float* blurred_d_sab = nullptr;
  float* grad = nullptr;  // H x W x C: += SSIM's gradient
};

D2GS_HD void ssim_grad_thread(int j, const SsimGradArgs& a) {
  const int p = j / a.channels, c = j % a.channels;
  const long long at = static_cast<long long>(c) * a.pixels + p;
  a.grad[j] += ssim_input_gradient(a.blurred_d_mu[at], a.a[j], a.blurred_d_saa[at], a.b[at], a.blurred_d_sab[at]);
}
using SsimGradKernel = render::kernels::PerItemKernel<SsimGradArgs, ssim_grad_thread>;

}  // namespace d2gs::train_kernels
