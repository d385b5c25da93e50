// The dropout masks and the densification statistic as kernels (train/kernels/dropout_kernels.hpp,
// densify_kernels.hpp) against train/dropout.cpp and train/densify.cpp: through the CPU emulator always,
// on the GPU when there is one. The masks take the CPU's own draws (the Rng stream jumped ahead in
// parallel, xoshiro_jump.hpp), so they and the stream's state afterwards must be the CPU's bit for bit;
// so must the statistic (the same float expression, IEEE square root).
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <string>

#include "d2gs/core/error.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/train/densify.hpp"
#include "d2gs/train/dropout.hpp"
#include "d2gs/train/kernels/optim.hpp"
#include "d2gs/train/kernels/xoshiro_jump.hpp"
#include "test_paths.hpp"

namespace d2gs::test {
namespace {

namespace emulate = render::kernels::emulate;
namespace tk = train_kernels;

bool bit_equal(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0);
}

void expect_same_stream(Rng a, Rng b, const std::string& what) {
  const auto sa = a.state(), sb = b.state();
  for (int k = 0; k < 4; ++k) EXPECT_EQ(sa.words[k], sb.words[k]) << what << " word " << k;
  EXPECT_EQ(a.uniform(), b.uniform()) << what;
}

TEST(XoshiroJump, PolynomialsAreXoshirosJumpAndLongJump) {
  // xoshiro256's published jump constants (Blackman & Vigna) are x^(2^128) and x^(2^192) mod P.
  const tk::XoshiroPolynomial jump = {0x180ec6d33cfd0abaull, 0xd5a61266f0c9392cull, 0xa9582618e03fc9aaull,
                                      0x39abdc4529b1661cull};
  const tk::XoshiroPolynomial long_jump = {0x76e15d3efefdcbbfull, 0xc5004e441c522fb3ull, 0x77710069854ee241ull,
                                           0x39109bb02acbe635ull};
  EXPECT_EQ(tk::xoshiro_jump_polynomial_pow2(128), jump);
  EXPECT_EQ(tk::xoshiro_jump_polynomial_pow2(192), long_jump);
  EXPECT_EQ(tk::xoshiro_jump_polynomial_pow2(20), tk::xoshiro_jump_polynomial(1u << 20));
}

TEST(XoshiroJump, DrawsAndAdvanceAreTheRngs) {
  Rng rng = Rng::stream(3, "dropout");
  auto state = rng.state();
  for (int i = 0; i < 1000; ++i) ASSERT_EQ(tk::xoshiro_next(state.words), rng.next_u64()) << i;
  EXPECT_EQ(tk::xoshiro_uniform(state.words), rng.uniform());
  for (std::uint64_t draws : {0ull, 1ull, 63ull, 64ull, 65ull, 1000ull, 123457ull}) {
    Rng stepped = Rng::stream(7, "x"), jumped = stepped;
    for (std::uint64_t i = 0; i < draws; ++i) stepped.uniform();
    tk::advance(jumped, draws);
    expect_same_stream(jumped, stepped, std::to_string(draws) + " draws");
  }
}

template <class Mask>
void expect_dropgaussian_equal(Mask kernel_mask, const std::string& what) {
  for (std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{63}, std::size_t{64}, std::size_t{65},
                        std::size_t{10007}, std::size_t{70000}})
    for (double rate : {0.0, 0.13, 0.2}) {
      Rng cpu_rng = Rng::stream(n + 1, "dropout"), kernel_rng = cpu_rng;
      cpu_rng.uniform();  // streams partway through
      kernel_rng.uniform();
      std::vector<float> cpu, kernel(3, -1.0f);
      dropgaussian_mask(n, rate, cpu_rng, cpu);
      kernel_mask(n, rate, kernel_rng, kernel);
      const std::string at = what + " n " + std::to_string(n) + " rate " + std::to_string(rate);
      EXPECT_TRUE(bit_equal(kernel, cpu)) << at;
      expect_same_stream(kernel_rng, cpu_rng, at);
    }
}

template <class Mask>
void expect_bernoulli_equal(const std::vector<float>& probabilities, Mask kernel_mask, const std::string& what) {
  for (bool compensate : {false, true}) {
    Rng cpu_rng = Rng::stream(probabilities.size(), "dropout"), kernel_rng = cpu_rng;
    std::vector<float> cpu, kernel;
    bernoulli_mask(probabilities, cpu_rng, cpu, compensate);
    kernel_mask(probabilities, kernel_rng, kernel, compensate);
    const std::string at = what + (compensate ? " compensated" : "");
    EXPECT_TRUE(bit_equal(kernel, cpu)) << at;
    expect_same_stream(kernel_rng, cpu_rng, at);
  }
}

std::vector<float> random_probabilities(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0.0f, 0.4f);
  std::vector<float> p(n);
  for (std::size_t i = 0; i < n; ++i) p[i] = i % 97 == 0 ? 1.0f : i % 89 == 0 ? 0.0f : u(rng);
  return p;
}

// D²GS's probabilities on fern: its SfM points as Gaussians, depths from view 0, kNN density scores.
std::vector<float> fern_probabilities() {
  SceneLoadOptions load;
  load.resolution = 8;
  const Scene scene = load_scene(shared_data() / "nerf_llff_data/fern", load);
  Gaussians model;
  model.resize(scene.sfm_points.size(), 0);
  for (std::size_t i = 0; i < model.size(); ++i)
    for (int k = 0; k < 3; ++k) model.means[3 * i + static_cast<std::size_t>(k)] = scene.sfm_points.positions[i][k];
  const DdDropOptions options;
  return dd_drop_probabilities(gaussian_depths(model, scene.cameras.at(0), options.depth_mode), density_scores(model),
                               options, 5000);
}

template <class Add>
void expect_gradient_stats_equal(Add kernel_add, const std::string& what) {
  const std::size_t n = 20011;
  GradientStats cpu, kernel;
  cpu.reset(n);
  kernel.reset(n);
  std::mt19937 rng(9);
  std::normal_distribution<float> g(0.0f, 1e-3f);
  for (int step = 0; step < 3; ++step) {
    std::vector<float> grad(2 * n);
    std::vector<int> radii(n);
    for (auto& v : grad) v = g(rng);
    for (std::size_t i = 0; i < n; ++i) radii[i] = static_cast<int>(rng() % 5) - 1;  // -1 … 3: some not visible
    cpu.add(grad, radii);
    kernel_add(kernel, grad, radii);
    EXPECT_TRUE(bit_equal(kernel.sums(), cpu.sums())) << what << " step " << step;
    EXPECT_TRUE(bit_equal(kernel.counts(), cpu.counts())) << what << " step " << step;
  }
  EXPECT_THROW(kernel_add(kernel, std::vector<float>(2), std::vector<int>(1)), Error);
}

TEST(EmulatedKernels, DropGaussianMaskEqualsTheCpuDrawForDraw) {
  for (auto schedule : emulate::kAllSchedules)
    expect_dropgaussian_equal([schedule](std::size_t n, double rate, Rng& rng, std::vector<float>& m) {
      tk::emulated_dropgaussian_mask(n, rate, rng, m, schedule);
    }, "emulated");
  Rng rng(1);
  std::vector<float> m;
  EXPECT_THROW(tk::emulated_dropgaussian_mask(10, 1.0, rng, m), Error);
}

TEST(EmulatedKernels, BernoulliMaskEqualsTheCpuDrawForDraw) {
  for (auto schedule : emulate::kAllSchedules) {
    const auto kernel = [schedule](const std::vector<float>& p, Rng& rng, std::vector<float>& m, bool compensate) {
      tk::emulated_bernoulli_mask(p, rng, m, compensate, schedule);
    };
    for (std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{65}, std::size_t{30001}})
      expect_bernoulli_equal(random_probabilities(n, static_cast<unsigned>(n)), kernel, "n " + std::to_string(n));
  }
}

TEST(EmulatedKernels, DdDropMaskOnFernEqualsTheCpu) {
  const auto p = fern_probabilities();
  ASSERT_GT(p.size(), 1000u);
  expect_bernoulli_equal(p, [](const std::vector<float>& probabilities, Rng& rng, std::vector<float>& m, bool compensate) {
    tk::emulated_bernoulli_mask(probabilities, rng, m, compensate);
  }, "fern");
}

TEST(EmulatedKernels, GradientStatsEqualTheCpuBitForBit) {
  for (auto schedule : emulate::kAllSchedules)
    expect_gradient_stats_equal([schedule](GradientStats& s, const std::vector<float>& g, const std::vector<int>& r) {
      tk::emulated_add_gradient_stats(s, g, r, schedule);
    }, "emulated");
}

TEST(DeviceKernels, DropoutMasksEqualTheCpuDrawForDraw) {
  if (cuda::device_count() == 0) {
    Rng rng(1);
    std::vector<float> m;
    EXPECT_THROW(tk::device_dropgaussian_mask(10, 0.1, rng, m), Error);
    GTEST_SKIP() << cuda::describe_device();
  }
  expect_dropgaussian_equal([](std::size_t n, double rate, Rng& rng, std::vector<float>& m) {
    tk::device_dropgaussian_mask(n, rate, rng, m);
  }, "device");
  const auto kernel = [](const std::vector<float>& p, Rng& rng, std::vector<float>& m, bool compensate) {
    tk::device_bernoulli_mask(p, rng, m, compensate);
  };
  expect_bernoulli_equal(random_probabilities(30001, 1), kernel, "random");
  expect_bernoulli_equal(fern_probabilities(), kernel, "fern");
}

TEST(DeviceKernels, GradientStatsEqualTheCpuBitForBit) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  expect_gradient_stats_equal([](GradientStats& s, const std::vector<float>& g, const std::vector<int>& r) {
    tk::device_add_gradient_stats(s, g, r);
  }, "device");
}

}  // namespace
}  // namespace d2gs::test
