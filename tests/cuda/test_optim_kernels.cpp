// Adam and the L1 loss as kernels (train/kernels/) against train/adam.cpp and train/losses.cpp: through the
// CPU emulator always, on the GPU when there is one. Adam's update and the L1 gradient are the same float
// expressions in the same order (and the .cu files are compiled with -fmad=false, with IEEE division and
// square roots), so they must agree bit for bit on both paths; the L1 value is a sum in another order.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>

#include "cuda/stage_compare.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/train/adam.hpp"
#include "d2gs/train/kernels/optim.hpp"
#include "d2gs/train/losses.hpp"

namespace d2gs::test {
namespace {

Gaussians random_gaussians(std::size_t n, unsigned seed, float scale) {
  Gaussians g;
  g.resize(n, 3);
  std::mt19937 rng(seed);
  std::normal_distribution<float> d(0.0f, scale);
  for (auto* a : {&g.means, &g.log_scales, &g.quats, &g.opacity_logits, &g.sh_dc, &g.sh_rest})
    for (auto& v : *a) v = d(rng);
  return g;
}

namespace emulate = render::kernels::emulate;

template <class AdamStep>
void expect_adam_equal(AdamStep kernel_step) {
  const std::size_t n = 5000;
  Gaussians cpu = random_gaussians(n, 1, 1.0f), gpu = cpu;
  AdamState cpu_state = Adam::make_state(cpu), gpu_state = Adam::make_state(gpu);
  const LearningRates lr;
  for (int step = 0; step < 4; ++step) {
    Gaussians grads = random_gaussians(n, 10 + step, step == 3 ? 1e-9f : 1e-2f);
    grads.quats[7] = 0.0f;
    const bool skip_opacity = step == 2;
    Adam::step(cpu, grads, cpu_state, lr, 1.6e-4f * (1.0f - 0.1f * step), skip_opacity);
    kernel_step(gpu, grads, gpu_state, lr, 1.6e-4f * (1.0f - 0.1f * step), skip_opacity);
    expect_bit_equal(gpu, cpu, "parameters");
    expect_bit_equal(gpu_state.exp_avg, cpu_state.exp_avg, "first moments");
    expect_bit_equal(gpu_state.exp_avg_sq, cpu_state.exp_avg_sq, "second moments");
    EXPECT_EQ(gpu_state.step, cpu_state.step);
  }
}

template <class L1>
void expect_l1_equal(L1 kernel_l1) {
  for (std::size_t count : {std::size_t{1}, std::size_t{255}, std::size_t{504 * 378 * 3}}) {
    std::mt19937 rng(static_cast<unsigned>(count));
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::vector<float> a(count), b(count), g0(count);
    for (std::size_t i = 0; i < count; ++i) {
      a[i] = u(rng);
      b[i] = i % 17 == 0 ? a[i] : u(rng);  // some zero differences: sign 0, no gradient
      g0[i] = u(rng) - 0.5f;
    }
    std::vector<float> g_cpu = g0, g_kernel = g0;
    const double v_cpu = l1_loss(a.data(), b.data(), count, g_cpu.data(), 0.8f);
    const double v_kernel = kernel_l1(a.data(), b.data(), count, g_kernel.data(), 0.8f);
    EXPECT_TRUE(bit_equal(g_kernel, g_cpu)) << count;
    EXPECT_NEAR(v_kernel, v_cpu, 1e-12 * v_cpu) << count;
    EXPECT_NEAR(kernel_l1(a.data(), b.data(), count, nullptr, 1.0f), v_cpu, 1e-12 * v_cpu) << count;
  }
  EXPECT_EQ(kernel_l1(nullptr, nullptr, 0, nullptr, 1.0f), 0.0);
}

TEST(EmulatedKernels, AdamEqualsAdamStepBitForBit) {
  for (auto schedule : emulate::kAllSchedules)
    expect_adam_equal([schedule](Gaussians& m, const Gaussians& g, AdamState& s, const LearningRates& lr, float means_lr,
                                 bool skip_opacity) {
      train_kernels::emulated_adam_step(m, g, s, lr, means_lr, skip_opacity, schedule);
    });
}
TEST(EmulatedKernels, L1GradientEqualsTheCpuBitForBit) {
  for (auto schedule : emulate::kAllSchedules)
    expect_l1_equal([schedule](const float* a, const float* b, std::size_t count, float* grad, float scale) {
      return train_kernels::emulated_l1_loss(a, b, count, grad, scale, schedule);
    });
}

TEST(DeviceKernels, AdamEqualsAdamStepBitForBit) {
  if (cuda::device_count() == 0) {
    Gaussians m = random_gaussians(3, 1, 1.0f);
    AdamState s = Adam::make_state(m);
    EXPECT_THROW(train_kernels::device_adam_step(m, m, s, LearningRates{}, 1e-4f), Error);
    GTEST_SKIP() << cuda::describe_device();
  }
  expect_adam_equal([](Gaussians& m, const Gaussians& g, AdamState& s, const LearningRates& lr, float means_lr,
                       bool skip_opacity) { train_kernels::device_adam_step(m, g, s, lr, means_lr, skip_opacity); });
}
TEST(DeviceKernels, L1GradientEqualsTheCpuBitForBit) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  expect_l1_equal([](const float* a, const float* b, std::size_t count, float* grad, float scale) {
    return train_kernels::device_l1_loss(a, b, count, grad, scale);
  });
}

}  // namespace
}  // namespace d2gs::test
