#include <gtest/gtest.h>

#include <random>

#include "d2gs/core/error.hpp"
#include "d2gs/render/activations.hpp"
#include "d2gs/render/cuda/device.hpp"

namespace d2gs {
namespace {

TEST(CudaDevice, DescribesItselfWithoutCrashing) {
  const int count = cuda::device_count();
  EXPECT_GE(count, 0);
  EXPECT_FALSE(cuda::describe_device().empty());
  if (count == 0) {
    // No GPU (CI, or a build without CUDA): asking for GPU work is a clean d2gs::Error.
    EXPECT_THROW(cuda::sigmoid_on_device({0.0f}), Error);
  }
}

TEST(CudaDevice, SigmoidKernelEqualsTheCpuFunction) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  std::mt19937 rng(1);
  std::normal_distribution<float> g(0.0f, 4.0f);
  std::vector<float> logits(100003);
  for (auto& v : logits) v = g(rng);
  const auto out = cuda::sigmoid_on_device(logits);
  ASSERT_EQ(out.size(), logits.size());
  for (std::size_t i = 0; i < logits.size(); ++i) EXPECT_NEAR(out[i], sigmoid(logits[i]), 2e-7f) << i;
}

}  // namespace
}  // namespace d2gs
