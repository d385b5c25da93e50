#pragma once
// The densification statistic (train/densify.cpp: GradientStats::add) as a kernel: one thread per
// Gaussian, add_gradient_stat of train/densify_math.hpp (the CPU's arithmetic), so the sums and counts
// are the CPU's bit for bit. Clone, split, prune and the opacity reset stay on the host for now.
#include "d2gs/render/kernels/block.hpp"
#include "d2gs/train/densify_math.hpp"

namespace d2gs::train_kernels {

struct GradientStatsArgs {
  int n = 0;
  const float* grad_mean2d_ndc = nullptr;  // n x 2
  const int* radii = nullptr;              // n
  float* sum = nullptr;                    // n
  float* count = nullptr;                  // n
};

D2GS_HD void gradient_stats_thread(int i, const GradientStatsArgs& a) {
  add_gradient_stat(i, a.grad_mean2d_ndc, a.radii, a.sum, a.count);
}
using GradientStatsKernel = render::kernels::PerItemKernel<GradientStatsArgs, gradient_stats_thread>;

}  // namespace d2gs::train_kernels
