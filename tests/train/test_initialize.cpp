#include <gtest/gtest.h>

#include <cmath>

#include "d2gs/render/activations.hpp"
#include "d2gs/train/initialize.hpp"

namespace d2gs {
namespace {

TEST(Initialize, GaussiansFromPointCloudFollowTheOriginalRecipe) {
  PointCloud cloud;
  // Four points on a unit square (each has two neighbours at 1 and one at sqrt 2) and one far away.
  cloud.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  cloud.colors = {{255, 0, 128}, {0, 0, 0}, {255, 255, 255}, {10, 20, 30}};
  const Gaussians g = gaussians_from_point_cloud(cloud, 3);
  ASSERT_EQ(g.size(), 4u);
  g.validate();
  const float expected_log_scale = std::log(std::sqrt((1.0f + 1.0f + 2.0f) / 3.0f));
  for (std::size_t i = 0; i < 4; ++i) {
    for (int d = 0; d < 3; ++d) EXPECT_NEAR(g.log_scales[i * 3 + d], expected_log_scale, 1e-6f);
    EXPECT_NEAR(sigmoid(g.opacity_logits[i]), 0.1f, 1e-6f);
    EXPECT_EQ(g.quats[i * 4], 1.0f);
    EXPECT_EQ(g.quats[i * 4 + 1], 0.0f);
  }
  EXPECT_NEAR(g.sh_dc[0] * kShC0 + 0.5f, 1.0f, 1e-6f);
  EXPECT_NEAR(g.sh_dc[2] * kShC0 + 0.5f, 128.0f / 255.0f, 1e-6f);
  for (float v : g.sh_rest) EXPECT_EQ(v, 0.0f);
  EXPECT_EQ(g.sh_rest.size(), 4u * 15u * 3u);
}

TEST(Initialize, CoincidentPointsGetTheFloorScale) {
  PointCloud cloud;
  cloud.positions.assign(5, {2, 2, 2});
  cloud.colors.assign(5, {0, 0, 0});
  const Gaussians g = gaussians_from_point_cloud(cloud, 0);
  EXPECT_NEAR(g.log_scales[0], std::log(std::sqrt(1e-7f)), 1e-5f);
  EXPECT_THROW(gaussians_from_point_cloud(PointCloud{}, 0), std::exception);
}

}  // namespace
}  // namespace d2gs
