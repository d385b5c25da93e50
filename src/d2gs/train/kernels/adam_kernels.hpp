#pragma once
// Adam, one thread per parameter value (gsplat's AdamCUDA), in the kernel shape of
// render/kernels/block.hpp: the update of train/adam.cpp, the same float expression in the same order.
#include <math.h>

#include "d2gs/render/kernels/block.hpp"

namespace d2gs::train_kernels {

using render::kernels::Thread;

// The per-step scalars of one parameter group, computed on the host as Adam::step does.
struct AdamScalars {
  float b1 = 0, b2 = 0, step_size = 0, inv_sqrt_bias2 = 0, eps = 0;
};

struct AdamArgs {
  int n = 0;
  float* param = nullptr;
  const float* grad = nullptr;
  float* exp_avg = nullptr;
  float* exp_avg_sq = nullptr;
  AdamScalars s;
};

D2GS_HD void adam_thread(int i, const AdamArgs& a) {
  a.exp_avg[i] = a.s.b1 * a.exp_avg[i] + (1.0f - a.s.b1) * a.grad[i];
  a.exp_avg_sq[i] = a.s.b2 * a.exp_avg_sq[i] + (1.0f - a.s.b2) * a.grad[i] * a.grad[i];
  a.param[i] -= a.s.step_size * a.exp_avg[i] / (sqrtf(a.exp_avg_sq[i]) * a.s.inv_sqrt_bias2 + a.s.eps);
}

using AdamKernel = render::kernels::PerItemKernel<AdamArgs, adam_thread>;

}  // namespace d2gs::train_kernels
