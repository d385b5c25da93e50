#pragma once
// The per-Gaussian decisions of the dropout masks (train/dropout.cpp), shared unchanged by the CPU and the
// CUDA backend's kernels (train/kernels/dropout_kernels.hpp). `u` is the Gaussian's uniform draw in
// [0, 1) (Rng::uniform). C++17, no standard library: nvcc compiles it.
#include "d2gs/core/host_device.hpp"

namespace d2gs {

// DropGaussian: dropped (0) with probability `rate`, else 1/(1 − rate) (keep_scale, rounded to float once).
D2GS_HD float dropgaussian_multiplier(double u, double rate, float keep_scale) {
  return u < rate ? 0.0f : keep_scale;
}

// DD-Drop's Bernoulli draw: dropped (0) with probability p; else 1, or 1/(1 − p) with `compensate`.
// u ∈ [0, 1): p = 1 always drops, so 1 − p > 0 wherever a Gaussian is kept.
D2GS_HD float bernoulli_multiplier(double u, float p, bool compensate) {
  return u < p ? 0.0f : compensate ? 1.0f / (1.0f - p) : 1.0f;
}

}  // namespace d2gs
