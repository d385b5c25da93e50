#include "d2gs/train/initialize.hpp"

#include <algorithm>
#include <cmath>

#include "d2gs/core/error.hpp"
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

}  // namespace d2gs
