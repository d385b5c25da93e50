#pragma once
// SSIM exactly as the 3DGS code and method.md §6: 11×11 Gaussian window (σ = 1.5), per channel, zero
// padding with "same" output size, C1 = 0.01², C2 = 0.03², mean of the SSIM map over C·H·W.
// The backward pass is written by hand (tests check it against finite differences in double).
//
// Images are interleaved H×W×C (as d2gs::Image). The window is separable, so every local mean is two
// 1-D passes; the adjoint of a zero-padded "same" filter with a symmetric kernel is the same filter.
#include <array>
#include <vector>

#include "d2gs/eval/ssim_math.hpp"  // kSsimWindow, kSsimSigma, kSsimC1, kSsimC2 and the per-pixel arithmetic

namespace d2gs {

// The normalised 1-D window: exp(−x²/2σ²) / Σ, x = −5 … 5, in double, then rounded to T.
template <typename T>
std::array<T, kSsimWindow> ssim_window();

// Reusable buffers for SSIM on images of one size (no allocation after the first call).
template <typename T>
class Ssim {
public:
  // A fixed second image (a training view's ground truth) with its local means and local second moments,
  // per channel (planar: channel c at c·W·H). Evaluating against it blurs 3 planes per channel instead of
  // 5; the value and gradient are bit-identical to evaluate(a, b, ...).
  struct Reference {
    int width = 0, height = 0, channels = 0;
    std::vector<T> b, mu_b, s_bb;
  };
  Reference reference(const T* b, int width, int height, int channels);

  // Mean SSIM of `a` against `b`. When `grad_a` is non-null, d(mean SSIM)/d a (same layout) scaled by
  // `grad_scale` (e.g. −0.2 for the loss term 0.2·(1 − SSIM)) is ADDED to it, as every loss's gradient is
  // (the trainer adds L1's first).
  T evaluate(const T* a, const T* b, int width, int height, int channels, T* grad_a = nullptr,
             T grad_scale = T(1));
  // The same against a precomputed reference(b, ...) (evaluate(a, b, ...) is this with reference(b, ...)).
  T evaluate(const T* a, const Reference& b, T* grad_a = nullptr, T grad_scale = T(1));

private:
  void resize(int width, int height);
  void blur(const T* in, T* out);  // planar, one channel
  int width_ = 0, height_ = 0;
  std::vector<T> a_, mu_a_, s_aa_, s_ab_, tmp_, d_mu_, d_saa_, d_sab_, acc_, map_;
  std::vector<double> row_sums_;
};

// Convenience: mean SSIM of two images (float inputs, double arithmetic).
double ssim(const float* a, const float* b, int width, int height, int channels);

extern template std::array<float, kSsimWindow> ssim_window<float>();
extern template std::array<double, kSsimWindow> ssim_window<double>();
extern template class Ssim<float>;
extern template class Ssim<double>;

}  // namespace d2gs
