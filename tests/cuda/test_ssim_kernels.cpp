// SSIM as kernels (train/kernels/ssim_kernels.hpp) against eval/ssim.cpp's Ssim<float>, which the trainer
// uses: through the CPU emulator always, on the GPU when there is one.
//
// Every per-pixel value is the CPU's arithmetic (eval/ssim_math.hpp) and every blur the same taps in the
// same order, each tap one fused multiply-add. The CPU's blur fuses its taps where its x86-64-v3/v4
// clones run (FMA: GCC contracts acc += w·s), so there the reference's planes, means and second moments
// and the gradient must be the CPU's bit for bit; on an x86-64 without FMA they differ by float rounding.
// The mean is a sum of the map in double in another order (block sums added in a fixed order) and the
// CPU rounds it to float: within 2^-24 of the CPU's float.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>

#include "d2gs/core/error.hpp"
#include "d2gs/core/image.hpp"
#include "d2gs/core/vector_clones.hpp"
#include "d2gs/eval/ssim.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/train/kernels/optim.hpp"
#include "d2gs/train/losses.hpp"
#include "test_paths.hpp"

namespace d2gs::test {
namespace {

namespace emulate = render::kernels::emulate;
constexpr emulate::Schedule kSchedules[] = {emulate::Schedule::Forward, emulate::Schedule::Reverse,
                                            emulate::Schedule::SyncVisibility};

// Whether the CPU's blur runs a clone with FMA (vector_clones.hpp), and so fuses its taps as the kernels do.
bool cpu_blur_fuses() {
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && !defined(D2GS_NO_TARGET_CLONES)
  return __builtin_cpu_supports("x86-64-v3");
#else
  return false;
#endif
}

// Bit for bit where the CPU fuses its blur taps; else within float rounding of values of order `scale`.
void expect_equal(const std::vector<float>& kernel, const std::vector<float>& cpu, float scale, const std::string& what) {
  ASSERT_EQ(kernel.size(), cpu.size()) << what;
  if (cpu_blur_fuses()) {
    std::size_t differ = 0, first = 0;
    for (std::size_t i = 0; i < cpu.size(); ++i)
      if (std::memcmp(&kernel[i], &cpu[i], sizeof(float)) != 0 && differ++ == 0) first = i;
    EXPECT_EQ(differ, 0u) << what << ": first at " << first << ": " << kernel[first] << " vs " << cpu[first];
    return;
  }
  for (std::size_t i = 0; i < cpu.size(); ++i) ASSERT_NEAR(kernel[i], cpu[i], 1e-5f * scale) << what << " at " << i;
}

struct Pair {
  int width = 0, height = 0, channels = 0;
  std::vector<float> a, b;
};

// A prediction a near a ground truth b (as in training), values in [0, 1].
Pair random_pair(int width, int height, int channels, unsigned seed) {
  Pair p{width, height, channels, {}, {}};
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  const std::size_t n = static_cast<std::size_t>(width) * height * channels;
  p.a.resize(n);
  p.b.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    p.b[i] = u(rng);
    p.a[i] = std::clamp(0.7f * p.b[i] + 0.3f * u(rng), 0.0f, 1.0f);
  }
  return p;
}

// Fern's first two views at 1/8 resolution (504 x 378): the ground truth is view 0, the prediction view
// 0 blended with view 1 and clamped, an SSIM near a training step's.
Pair fern_pair() {
  const auto dir = shared_data() / "nerf_llff_data/fern/images_8";
  const Image v0 = read_image(dir / "image000.png"), v1 = read_image(dir / "image001.png");
  Pair p{v0.width, v0.height, v0.channels, {}, v0.pixels};
  p.a.resize(v0.pixels.size());
  for (std::size_t i = 0; i < p.a.size(); ++i) p.a[i] = std::clamp(0.8f * v0.pixels[i] + 0.25f * v1.pixels[i] - 0.02f, 0.0f, 1.0f);
  return p;
}

template <class Reference>
void expect_reference_equal(const Pair& p, Reference kernel_reference, const std::string& what) {
  Ssim<float> cpu;
  const auto expected = cpu.reference(p.b.data(), p.width, p.height, p.channels);
  const auto got = kernel_reference(p.b.data(), p.width, p.height, p.channels);
  EXPECT_EQ(got.width, expected.width);
  EXPECT_EQ(got.height, expected.height);
  EXPECT_EQ(got.channels, expected.channels);
  EXPECT_EQ(got.b, expected.b) << what;  // the de-interleaved planes: copies
  expect_equal(got.mu_b, expected.mu_b, 1.0f, what + " mu_b");
  expect_equal(got.s_bb, expected.s_bb, 1.0f, what + " s_bb");
}

// Value and gradient of kernel_ssim against Ssim<float>::evaluate, with the CPU's reference statistics.
// Both add their gradient to a buffer that already holds the L1 gradient, as in the training step (the
// CPU's l1_loss first): the sums must agree, so a kernel that wrote over the buffer would fail (the L1
// gradient, of order 1/count, is far above the tolerance, 2e-4/count).
template <class Evaluate>
void expect_ssim_equal(const Pair& p, Evaluate kernel_ssim, const std::string& what) {
  Ssim<float> cpu;
  const auto ref = cpu.reference(p.b.data(), p.width, p.height, p.channels);
  const float grad_scale = -0.2f;  // the trainer's: the loss term 0.2·(1 − SSIM)
  std::vector<float> l1_grad(p.a.size(), 0.0f);
  l1_loss(p.a.data(), p.b.data(), p.a.size(), l1_grad.data(), 1.0f);
  std::vector<float> g_cpu = l1_grad, g_kernel = l1_grad;
  const float v_cpu = cpu.evaluate(p.a.data(), ref, g_cpu.data(), grad_scale);
  const double v_kernel = kernel_ssim(p.a.data(), ref, g_kernel.data(), grad_scale);
  EXPECT_NEAR(v_kernel, v_cpu, 0x1p-24) << what;
  EXPECT_NEAR(kernel_ssim(p.a.data(), ref, nullptr, 1.0f), v_kernel, 1e-12) << what << " (value only)";
  const double count = static_cast<double>(p.a.size());
  expect_equal(g_kernel, g_cpu, static_cast<float>(0.2 * 20.0 / count), what + " gradient (added to L1's)");
  // The buffer held L1's gradient: no test of the sum would notice an overwrite if it had been zero.
  ASSERT_NE(std::count(l1_grad.begin(), l1_grad.end(), 0.0f), static_cast<std::ptrdiff_t>(l1_grad.size())) << what;
}

TEST(EmulatedKernels, SsimReferenceEqualsTheCpu) {
  RecordProperty("cpu_blur_fuses", cpu_blur_fuses() ? "yes" : "no");
  for (auto schedule : kSchedules) {
    const auto kernel = [schedule](const float* b, int w, int h, int c) {
      return train_kernels::emulated_ssim_reference(b, w, h, c, schedule);
    };
    expect_reference_equal(random_pair(37, 23, 3, 1), kernel, "37x23x3");
    expect_reference_equal(random_pair(7, 4, 1, 2), kernel, "7x4x1 (smaller than the window)");
    expect_reference_equal(random_pair(64, 48, 2, 3), kernel, "64x48x2");
  }
}

TEST(EmulatedKernels, SsimValueAndGradientEqualTheCpu) {
  for (auto schedule : kSchedules) {
    const auto kernel = [schedule](const float* a, const Ssim<float>::Reference& ref, float* grad, float scale) {
      return train_kernels::emulated_ssim(a, ref, grad, scale, schedule);
    };
    expect_ssim_equal(random_pair(37, 23, 3, 4), kernel, "37x23x3");
    expect_ssim_equal(random_pair(7, 4, 1, 5), kernel, "7x4x1");
    expect_ssim_equal(random_pair(120, 90, 3, 6), kernel, "120x90x3");  // 126 blocks of partial sums
  }
  // Identical images: SSIM 1, up to rounding.
  const Pair p = random_pair(40, 30, 3, 7);
  Ssim<float> cpu;
  const auto ref = cpu.reference(p.b.data(), p.width, p.height, p.channels);
  EXPECT_NEAR(train_kernels::emulated_ssim(p.b.data(), ref), 1.0, 1e-6);
}

TEST(EmulatedKernels, SsimOnFernEqualsTheCpu) {
  const Pair p = fern_pair();
  ASSERT_EQ(p.width, 504);
  ASSERT_EQ(p.height, 378);
  expect_reference_equal(p, [](const float* b, int w, int h, int c) {
    return train_kernels::emulated_ssim_reference(b, w, h, c);
  }, "fern");
  for (auto schedule : {emulate::Schedule::Forward, emulate::Schedule::SyncVisibility})
    expect_ssim_equal(p, [schedule](const float* a, const Ssim<float>::Reference& ref, float* grad, float scale) {
      return train_kernels::emulated_ssim(a, ref, grad, scale, schedule);
    }, "fern");
}

TEST(EmulatedKernels, SsimRejectsABadReference) {
  Ssim<float>::Reference ref;
  EXPECT_THROW(train_kernels::emulated_ssim(nullptr, ref), Error);
  ref.width = ref.height = ref.channels = 2;
  ref.b.resize(7);
  EXPECT_THROW(train_kernels::emulated_ssim(nullptr, ref), Error);
}

// On a GPU: the blur's fmaf taps are correctly rounded as glibc's, the map's arithmetic is compiled with
// -fmad=false (IEEE division), so where the CPU fuses its blur the results are its bits; the sum's order
// is fixed, so the value is the emulator's bit for bit.
TEST(DeviceKernels, SsimEqualsTheCpu) {
  if (cuda::device_count() == 0) {
    const Pair p = random_pair(8, 8, 1, 1);
    EXPECT_THROW(train_kernels::device_ssim_reference(p.b.data(), 8, 8, 1), Error);
    GTEST_SKIP() << cuda::describe_device();
  }
  const auto reference = [](const float* b, int w, int h, int c) {
    return train_kernels::device_ssim_reference(b, w, h, c);
  };
  const auto evaluate = [](const float* a, const Ssim<float>::Reference& ref, float* grad, float scale) {
    return train_kernels::device_ssim(a, ref, grad, scale);
  };
  for (const Pair& p : {random_pair(37, 23, 3, 4), random_pair(120, 90, 3, 6), fern_pair()}) {
    const std::string what = std::to_string(p.width) + "x" + std::to_string(p.height);
    expect_reference_equal(p, reference, what);
    expect_ssim_equal(p, evaluate, what);
    Ssim<float> cpu;
    const auto ref = cpu.reference(p.b.data(), p.width, p.height, p.channels);
    EXPECT_EQ(train_kernels::device_ssim(p.a.data(), ref), train_kernels::emulated_ssim(p.a.data(), ref)) << what;
  }
}

}  // namespace
}  // namespace d2gs::test
