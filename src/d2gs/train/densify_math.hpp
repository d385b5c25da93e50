#pragma once
// The per-Gaussian arithmetic of the densification statistic (train/densify.cpp: GradientStats::add),
// shared unchanged by the CPU and the CUDA backend's kernel (train/kernels/densify_kernels.hpp).
// C++17, no standard library: nvcc compiles it.
#include <math.h>

#include "d2gs/render/host_device.hpp"

namespace d2gs {

// Gaussian i, if visible (radius > 0): sum += ‖∂L/∂mean2d (NDC)‖, count += 1.
D2GS_HD void add_gradient_stat(int i, const float* grad_mean2d_ndc, const int* radii, float* sum, float* count) {
  if (radii[i] <= 0) return;
  const float gx = grad_mean2d_ndc[2 * i], gy = grad_mean2d_ndc[2 * i + 1];
  sum[i] += sqrtf(gx * gx + gy * gy);
  count[i] += 1.0f;
}

}  // namespace d2gs
