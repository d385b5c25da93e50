#include "d2gs/train/initialize.hpp"

#include <algorithm>
#include <cmath>

#include "d2gs/core/error.hpp"
#include "d2gs/core/percentile.hpp"
#include "d2gs/core/random.hpp"
#include "d2gs/geometry/knn.hpp"
#include "d2gs/render/activations.hpp"

namespace d2gs {

Gaussians gaussians_from_point_cloud(const PointCloud& cloud, int sh_degree, float initial_opacity) {
  if (cloud.empty()) fail("initial point cloud is empty");
  if (cloud.colors.size() != cloud.positions.size()) fail("initial point cloud: colours and positions differ in count");
  if (!(initial_opacity > 0.0f && initial_opacity < 1.0f)) fail("initial opacity must be in (0, 1)");
  const std::size_t n = cloud.size();
  Gaussians g;
  g.resize(n, sh_degree);
  for (std::size_t i = 0; i < n; ++i)
    for (int d = 0; d < 3; ++d) g.means[i * 3 + d] = cloud.positions[i][d];
  const auto dist2 = knn_mean_distance(g.means.data(), n, 3, KnnStatistic::MeanSquaredDistance);
  const float logit = inverse_sigmoid(initial_opacity);
  for (std::size_t i = 0; i < n; ++i) {
    const float log_scale = std::log(std::sqrt(std::max(dist2[i], 1e-7f)));
    for (int d = 0; d < 3; ++d) {
      g.log_scales[i * 3 + d] = log_scale;
      g.sh_dc[i * 3 + d] = (static_cast<float>(cloud.colors[i][d]) / 255.0f - 0.5f) / kShC0;
    }
    g.opacity_logits[i] = logit;
  }
  return g;
}

RandomInitRange random_init_depth_range(const Scene& scene, const std::vector<int>& train_views, float extent) {
  RandomInitRange r{0.5 * extent, 50.0 * extent, false};
  double near = 0, far = 0;
  bool any = false;
  for (int v : train_views) {
    const Camera& cam = scene.cameras[static_cast<std::size_t>(v)];
    std::vector<double> depths;
    for (const auto& x : scene.sfm_points.positions) {
      const glm::dvec3 p = cam.R_world_to_cam * glm::dvec3(x) + cam.t_world_to_cam;
      if (p.z <= 0) continue;
      const double u = cam.fx * p.x / p.z + cam.cx, w = cam.fy * p.y / p.z + cam.cy;
      if (u >= 0 && u <= cam.width && w >= 0 && w <= cam.height) depths.push_back(p.z);
    }
    if (depths.size() < 20) return r;  // too few points in this view: no bounds
    const double n = percentile(depths, 0.1), f = percentile(depths, 99.9);
    near = any ? std::min(near, n) : n;
    far = any ? std::max(far, f) : f;
    any = true;
  }
  if (any && near > 0 && far > near) r = {near, far, true};
  return r;
}

PointCloud random_point_cloud(const Scene& scene, const std::vector<int>& train_views, int count,
                              const RandomInitRange& range, std::uint64_t seed) {
  if (!(range.near > 0 && range.far > range.near))
    fail("random init: the depth range must satisfy 0 < near < far, got {} … {}", range.near, range.far);
  if (train_views.empty()) fail("random init: no training views");
  Rng rng = Rng::stream(seed, "random-init");
  PointCloud cloud;
  cloud.positions.reserve(static_cast<std::size_t>(count));
  const double inv_near = 1.0 / range.near, inv_far = 1.0 / range.far;
  for (int i = 0; i < count; ++i) {
    const Camera& cam = scene.cameras[static_cast<std::size_t>(train_views[rng.below(train_views.size())])];
    const double px = rng.uniform() * cam.width, py = rng.uniform() * cam.height;
    const double depth = 1.0 / (inv_far + rng.uniform() * (inv_near - inv_far));
    const glm::dvec3 p_cam((px - cam.cx) / cam.fx * depth, (py - cam.cy) / cam.fy * depth, depth);
    const glm::dvec3 p = cam.R_cam_to_world() * (p_cam - cam.t_world_to_cam);
    cloud.positions.emplace_back(glm::vec3(p));
    cloud.colors.emplace_back(static_cast<std::uint8_t>(rng.below(256)), static_cast<std::uint8_t>(rng.below(256)),
                              static_cast<std::uint8_t>(rng.below(256)));
  }
  return cloud;
}

}  // namespace d2gs
