#include "d2gs/geometry/fusion.hpp"

#include <algorithm>
#include <cmath>

#include "d2gs/core/error.hpp"

namespace d2gs {

glm::dvec3 backproject(const Camera& c, int x, int y, double z) {
  const glm::dvec3 p_cam((x + 0.5 - c.cx) / c.fx * z, (y + 0.5 - c.cy) / c.fy * z, z);
  return c.R_cam_to_world() * (p_cam - c.t_world_to_cam);
}

DepthMap merge_depth_candidates(const std::vector<const DepthMap*>& candidates, double tol) {
  if (candidates.empty()) fail("depth fusion: no depth candidates");
  DepthMap out;
  out.width = candidates[0]->width;
  out.height = candidates[0]->height;
  for (const auto* m : candidates)
    if (m->width != out.width || m->height != out.height) fail("depth fusion: candidate maps differ in size");
  out.depth.assign(static_cast<std::size_t>(out.width) * out.height, 0.0f);
  std::vector<float> v;
  for (std::size_t i = 0; i < out.depth.size(); ++i) {
    v.clear();
    for (const auto* m : candidates)
      if (m->depth[i] > 0.0f) v.push_back(m->depth[i]);
    if (v.empty()) continue;
    std::sort(v.begin(), v.end());
    const double median = v[(v.size() - 1) / 2];
    double sum = 0.0;
    std::size_t n = 0;
    for (float d : v)
      if (std::abs(d - median) <= tol * median) sum += d, ++n;
    if (2 * n > v.size()) out.depth[i] = static_cast<float>(sum / static_cast<double>(n));
  }
  return out;
}

std::vector<DepthMap> filter_consistent_depths(const std::vector<const Camera*>& cameras,
                                               const std::vector<DepthMap>& depth, const FusionOptions& o) {
  if (cameras.size() != depth.size()) fail("depth fusion: {} cameras but {} depth maps", cameras.size(), depth.size());
  std::vector<DepthMap> out = depth;
#pragma omp parallel for schedule(dynamic)
  for (std::ptrdiff_t ii = 0; ii < static_cast<std::ptrdiff_t>(cameras.size()); ++ii) {
    const auto i = static_cast<std::size_t>(ii);
    const Camera& ci = *cameras[i];
    for (int y = 0; y < ci.height; ++y)
      for (int x = 0; x < ci.width; ++x) {
        float& d = out[i].depth[static_cast<std::size_t>(y) * ci.width + x];
        if (!(d > 0.0f)) continue;
        const glm::dvec3 X = backproject(ci, x, y, d);
        int agree = 0;
        for (std::size_t j = 0; j < cameras.size() && agree < o.min_consistent_views; ++j) {
          if (j == i) continue;
          const Camera& cj = *cameras[j];
          const glm::dvec3 p = cj.R_world_to_cam * X + cj.t_world_to_cam;
          if (!(p.z > 0.0)) continue;
          const double u = cj.fx * p.x / p.z + cj.cx, v = cj.fy * p.y / p.z + cj.cy;
          if (!(u >= 0 && v >= 0 && u < cj.width && v < cj.height)) continue;
          const float dj = depth[j].at(static_cast<int>(u), static_cast<int>(v));
          if (dj > 0.0f && std::abs(p.z - dj) <= o.relative_tolerance * dj) ++agree;
        }
        if (agree < o.min_consistent_views) d = 0.0f;
      }
  }
  return out;
}

PointCloud fuse_depth_maps(const std::vector<const Camera*>& cameras, const std::vector<const Image*>& images,
                           const std::vector<DepthMap>& depth, int stride) {
  if (stride < 1) fail("depth fusion: pixel stride must be at least 1, got {}", stride);
  PointCloud cloud;
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    const Camera& c = *cameras[i];
    const Image& img = *images[i];
    for (int y = stride / 2; y < c.height; y += stride)
      for (int x = stride / 2; x < c.width; x += stride) {
        const float d = depth[i].at(x, y);
        if (!(d > 0.0f)) continue;
        cloud.positions.emplace_back(glm::vec3(backproject(c, x, y, d)));
        glm::u8vec3 rgb;
        for (int k = 0; k < 3; ++k)
          rgb[k] = static_cast<std::uint8_t>(
              std::lround(std::clamp(img.at(x, y, std::min(k, img.channels - 1)), 0.0f, 1.0f) * 255.0f));
        cloud.colors.push_back(rgb);
      }
  }
  return cloud;
}

}  // namespace d2gs
