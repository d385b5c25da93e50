#pragma once
// DropGaussian's and DD-Drop's masks (train/dropout.cpp: dropgaussian_mask, bernoulli_mask) as a kernel
// with the CPU's random draws: Gaussian i takes the i-th uniform of the Rng stream, as on the CPU.
// Thread j draws the uniforms of Gaussians [j·L, (j + 1)·L) in order (L = kDrawsPerThread), from the
// stream's state jumped j·L draws ahead (xoshiro_jump.hpp: the jump table's polynomials for L·2^b
// draws, applied for the set bits of j); the last thread writes the state after the n-th draw, so the
// host's stream continues where the CPU's would. Per-Gaussian decisions: train/dropout_math.hpp.
#include <stdint.h>

#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/dropout_math.hpp"
#include "d2gs/train/kernels/xoshiro_jump.hpp"

namespace d2gs::train_kernels {

inline constexpr int kDrawsPerThread = 64;
inline constexpr int kJumpBits = 26;  // chunks < 2^26: up to 2^32 Gaussians

struct DropoutMaskArgs {
  int n = 0;       // threads: chunks of kDrawsPerThread Gaussians
  int count = 0;   // Gaussians
  uint64_t state[4] = {0, 0, 0, 0};  // the stream before the first draw
  const uint64_t* jumps = nullptr;   // kJumpBits polynomials of 4 words: kDrawsPerThread · 2^b draws
  // DD-Drop when probabilities is set (bernoulli_multiplier), else DropGaussian (dropgaussian_multiplier).
  const float* probabilities = nullptr;
  bool compensate = false;
  double rate = 0;
  float keep_scale = 1;
  float* multiplier = nullptr;  // count
  uint64_t* end_state = nullptr;  // 4 words: the stream after the count-th draw
};

D2GS_HD void dropout_mask_thread(int j, const DropoutMaskArgs& a) {
  uint64_t s[4] = {a.state[0], a.state[1], a.state[2], a.state[3]};
  for (int b = 0; b < kJumpBits; ++b)
    if ((j >> b) & 1) xoshiro_apply(s, a.jumps + 4 * b);
  const int begin = j * kDrawsPerThread;
  const int end = a.count - begin < kDrawsPerThread ? a.count : begin + kDrawsPerThread;
  for (int i = begin; i < end; ++i) {
    const double u = xoshiro_uniform(s);
    a.multiplier[i] = a.probabilities ? bernoulli_multiplier(u, a.probabilities[i], a.compensate)
                                      : dropgaussian_multiplier(u, a.rate, a.keep_scale);
  }
  if (j == a.n - 1)
    for (int k = 0; k < 4; ++k) a.end_state[k] = s[k];
}
using DropoutMaskKernel = render::kernels::PerItemKernel<DropoutMaskArgs, dropout_mask_thread>;

}  // namespace d2gs::train_kernels
