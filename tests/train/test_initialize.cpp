#include <gtest/gtest.h>

#include <cmath>

#include <glm/glm.hpp>

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

// One camera at the origin looking along +z, 200 x 100 pixels, f = 100.
Scene one_camera_scene() {
  Scene scene;
  Camera c;
  c.width = 200;
  c.height = 100;
  c.fx = c.fy = 100;
  c.cx = 100;
  c.cy = 50;
  scene.cameras.push_back(c);
  return scene;
}

TEST(Initialize, RandomInitDepthRangeIsTheLlffBoundsOfTheVisiblePoints) {
  Scene scene = one_camera_scene();
  for (int k = 1; k <= 1000; ++k) {  // in view at depths 1 … 1000
    scene.sfm_points.positions.emplace_back(0.1f * static_cast<float>(k) / 1000.0f, 0.0f, static_cast<float>(k));
    scene.sfm_points.colors.push_back({0, 0, 0});
  }
  for (glm::vec3 x : {glm::vec3(0, 0, -5), glm::vec3(500, 0, 10)}) {  // behind the camera; outside the image
    scene.sfm_points.positions.push_back(x);
    scene.sfm_points.colors.push_back({0, 0, 0});
  }
  const RandomInitRange r = random_init_depth_range(scene, {0}, 2.0f);
  EXPECT_TRUE(r.from_dataset_points);
  // numpy.percentile(range(1, 1001), [0.1, 99.9]) = 1.999, 999.001
  EXPECT_NEAR(r.near, 1.999, 1e-9);
  EXPECT_NEAR(r.far, 999.001, 1e-9);

  // No dataset points: 0.5 and 50 scene extents.
  const RandomInitRange fallback = random_init_depth_range(one_camera_scene(), {0}, 2.0f);
  EXPECT_FALSE(fallback.from_dataset_points);
  EXPECT_EQ(fallback.near, 1.0);
  EXPECT_EQ(fallback.far, 100.0);
}

TEST(Initialize, RandomPointCloudHasUniformInverseDepthInsideTheRange) {
  const Scene scene = one_camera_scene();
  const RandomInitRange r{2.0, 50.0, true};
  const PointCloud cloud = random_point_cloud(scene, {0}, 20000, r, 7);
  ASSERT_EQ(cloud.size(), 20000u);
  double mean_inverse = 0;
  for (const auto& x : cloud.positions) {
    ASSERT_GE(x.z, 2.0f * (1 - 1e-6f));
    ASSERT_LE(x.z, 50.0f * (1 + 1e-6f));
    const double u = 100.0 * x.x / x.z + 100.0, w = 100.0 * x.y / x.z + 50.0;  // on a pixel ray
    ASSERT_GE(u, -1e-3);
    ASSERT_LE(u, 200 + 1e-3);
    ASSERT_GE(w, -1e-3);
    ASSERT_LE(w, 100 + 1e-3);
    mean_inverse += 1.0 / x.z;
  }
  mean_inverse /= 20000.0;
  // Uniform on [1/50, 1/2]: mean 0.26, standard error 0.139 / sqrt(20000) ≈ 0.001.
  EXPECT_NEAR(mean_inverse, 0.26, 0.004);
  EXPECT_EQ(random_point_cloud(scene, {0}, 50, r, 7).positions, random_point_cloud(scene, {0}, 50, r, 7).positions);
  EXPECT_THROW(random_point_cloud(scene, {0}, 10, RandomInitRange{5.0, 5.0, false}, 7), std::exception);
  EXPECT_THROW(random_point_cloud(scene, {}, 10, r, 7), std::exception);
}

}  // namespace
}  // namespace d2gs
