#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "d2gs/core/error.hpp"
#include "d2gs/render/activations.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/projection_math.hpp"

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

TEST(CudaDevice, ProjectionKernelEqualsTheCpuStage) {
  std::mt19937 rng(4);
  std::normal_distribution<float> g(0.0f, 1.0f);
  const int n = 5000;
  std::vector<float> means(3 * n), scales(3 * n), quats(4 * n);
  for (int i = 0; i < n; ++i) {
    means[3 * i] = 2.0f * g(rng);
    means[3 * i + 1] = 1.5f * g(rng);
    means[3 * i + 2] = 4.0f + 3.0f * g(rng);  // some behind the near plane
    for (int k = 0; k < 3; ++k) scales[3 * i + k] = -3.0f + 0.7f * g(rng);
    for (int k = 0; k < 4; ++k) quats[4 * i + k] = g(rng);
  }
  cuda::DeviceCamera cam;
  cam.width = 504;
  cam.height = 378;
  cam.R[0] = cam.R[4] = cam.R[8] = 1.0f;
  cam.fx = cam.fy = 407.0f;
  cam.cx = 240.0f;  // off-centre principal point
  cam.cy = 189.0f;
  if (cuda::device_count() == 0) {
    EXPECT_THROW(cuda::project_on_device(means, scales, quats, cam), Error);
    GTEST_SKIP() << cuda::describe_device();
  }
  const auto gpu = cuda::project_on_device(means, scales, quats, cam);
  render::CameraParams<float> c;
  c.width = cam.width;
  c.height = cam.height;
  c.fx = cam.fx;
  c.fy = cam.fy;
  c.cx = cam.cx;
  c.cy = cam.cy;
  render::set_jacobian_limits(c);
  // nvcc contracts a*b+c into FMAs, so values sit within float rounding of the CPU's and a radius on a
  // ceil() boundary may differ by one pixel.
  int visible = 0, culling_mismatch = 0;
  for (int i = 0; i < n; ++i) {
    render::ProjectionState<float> st;
    float m2[2] = {0, 0}, cn[3] = {0, 0, 0}, z = 0;
    int r = 0;
    if (!render::project_gaussian(&means[3 * i], &scales[3 * i], &quats[4 * i], c, m2, cn, z, r, st)) r = 0;
    culling_mismatch += (gpu.radii[i] == 0) != (r == 0);
    if (r == 0 || gpu.radii[i] == 0) continue;
    EXPECT_LE(std::abs(gpu.radii[i] - r), 1) << i;
    ++visible;
    EXPECT_NEAR(gpu.mean2d[2 * i], m2[0], 1e-3f);
    EXPECT_NEAR(gpu.mean2d[2 * i + 1], m2[1], 1e-3f);
    EXPECT_NEAR(gpu.depth[i], z, 1e-5f * z);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(gpu.conic[3 * i + k], cn[k], 1e-4f * (1.0f + std::abs(cn[k])));
  }
  EXPECT_GT(visible, n / 2);
  EXPECT_LE(culling_mismatch, 2);
}

}  // namespace
}  // namespace d2gs
