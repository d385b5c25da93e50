#include "d2gs/geometry/patch_match_fusion.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

#include "d2gs/core/error.hpp"
#include "d2gs/geometry/fusion.hpp"

namespace d2gs {

void validate(const PatchMatchFusionOptions& o) {
  if (!(o.max_reprojection_px > 0)) fail("fusion: max reprojection error must be positive, got {}", o.max_reprojection_px);
  if (!(o.max_relative_depth > 0)) fail("fusion: max relative depth error must be positive, got {}", o.max_relative_depth);
  if (!(o.max_normal_deg > 0 && o.max_normal_deg <= 180)) fail("fusion: max normal angle must be in (0, 180], got {}", o.max_normal_deg);
  if (o.max_traversal_depth < 1) fail("fusion: max traversal depth must be at least 1, got {}", o.max_traversal_depth);
  if (o.min_pixels < 1) fail("fusion: min pixels per point must be at least 1, got {}", o.min_pixels);
  if (o.pixel_stride < 1) fail("fusion: pixel stride must be at least 1, got {}", o.pixel_stride);
  if (!(o.max_color_difference >= 0 && o.max_color_difference <= 1))
    fail("fusion: max colour difference must be in [0, 1] (0: off), got {}", o.max_color_difference);
  if (!(o.color_visibility_margin >= 1 && o.color_visibility_margin <= 2))
    fail("fusion: colour visibility margin must be in [1, 2], got {}", o.color_visibility_margin);
}

PointCloud fuse_patch_match(const std::vector<const Camera*>& cameras, const std::vector<const Image*>& images,
                            const std::vector<PatchMatchMap>& maps, const PatchMatchFusionOptions& o,
                            PatchMatchFusionStats* stats) {
  validate(o);
  const std::size_t n = cameras.size();
  if (images.size() != n || maps.size() != n)
    fail("fusion: {} cameras, {} images and {} depth maps", n, images.size(), maps.size());
  for (std::size_t i = 0; i < n; ++i) {
    const Camera& c = *cameras[i];
    const DepthMap& d = maps[i].depth;
    if (d.width != c.width || d.height != c.height || images[i]->width != c.width || images[i]->height != c.height ||
        maps[i].normals.size() != d.depth.size())
      fail("fusion: {}: depth map, normal map and image must have the camera's size {}x{}", c.image_name, c.width,
           c.height);
  }
  std::vector<std::vector<std::uint8_t>> taken(n);
  for (std::size_t i = 0; i < n; ++i) taken[i].assign(maps[i].depth.depth.size(), 0);
  const double cos_max_normal = std::cos(glm::radians(o.max_normal_deg));
  const double max_reproj_sq = o.max_reprojection_px * o.max_reprojection_px;

  struct Node {
    int view, x, y, depth;
  };
  std::vector<Node> queue;  // reused: no allocation per pixel once grown
  PointCloud cloud;
  for (std::size_t seed_view = 0; seed_view < n; ++seed_view) {
    const Camera& sc = *cameras[seed_view];
    for (int sy = 0; sy < sc.height; ++sy)
      for (int sx = 0; sx < sc.width; ++sx) {
        const std::size_t sp = static_cast<std::size_t>(sy) * sc.width + sx;
        if (taken[seed_view][sp] || !(maps[seed_view].depth.depth[sp] > 0.0f)) continue;
        queue.clear();
        queue.push_back({static_cast<int>(seed_view), sx, sy, 0});
        glm::dvec3 ref_point(0.0), ref_normal(0.0), sum_p(0.0), sum_n(0.0), sum_c(0.0);
        int pixels = 0;
        while (!queue.empty()) {
          const Node nd = queue.back();
          queue.pop_back();
          const auto vi = static_cast<std::size_t>(nd.view);
          const Camera& c = *cameras[vi];
          const std::size_t p = static_cast<std::size_t>(nd.y) * c.width + nd.x;
          if (taken[vi][p]) continue;
          const double z = maps[vi].depth.depth[p];
          if (!(z > 0.0)) continue;
          const glm::dvec3 normal = c.R_cam_to_world() * glm::dvec3(maps[vi].normals[p]);
          if (nd.depth > 0) {
            // Agreement with the first pixel's point: depth, reprojection, normal.
            const glm::dvec3 q = c.R_world_to_cam * ref_point + c.t_world_to_cam;
            if (!(q.z > 0.0) || std::abs(q.z - z) > o.max_relative_depth * z) continue;
            const double du = c.fx * q.x / q.z + c.cx - (nd.x + 0.5), dv = c.fy * q.y / q.z + c.cy - (nd.y + 0.5);
            if (du * du + dv * dv > max_reproj_sq) continue;
            if (glm::dot(ref_normal, normal) < cos_max_normal) continue;
          }
          taken[vi][p] = 1;
          const glm::dvec3 X = backproject(c, nd.x, nd.y, z);
          if (nd.depth == 0) ref_point = X, ref_normal = normal;
          sum_p += X, sum_n += normal;
          const Image& img = *images[vi];
          for (int k = 0; k < 3; ++k) sum_c[k] += img.at(nd.x, nd.y, std::min(k, img.channels - 1));
          ++pixels;
          if (nd.depth + 1 >= o.max_traversal_depth) continue;
          for (std::size_t j = 0; j < n; ++j) {
            if (j == vi) continue;
            const Camera& cj = *cameras[j];
            const glm::dvec3 q = cj.R_world_to_cam * X + cj.t_world_to_cam;
            if (!(q.z > 0.0)) continue;
            const double u = cj.fx * q.x / q.z + cj.cx, v = cj.fy * q.y / q.z + cj.cy;
            if (!(u >= 0.0 && v >= 0.0 && u < cj.width && v < cj.height)) continue;
            const int jx = static_cast<int>(u), jy = static_cast<int>(v);
            if (!taken[j][static_cast<std::size_t>(jy) * cj.width + jx]) queue.push_back({static_cast<int>(j), jx, jy, nd.depth + 1});
          }
        }
        if (pixels < o.min_pixels) continue;
        if (sx % o.pixel_stride != o.pixel_stride / 2 || sy % o.pixel_stride != o.pixel_stride / 2) continue;
        const double len = glm::length(sum_n);
        if (!(len > 1e-9)) continue;
        cloud.positions.emplace_back(glm::vec3(sum_p / static_cast<double>(pixels)));
        cloud.normals.emplace_back(glm::vec3(sum_n / len));
        glm::u8vec3 rgb;
        for (int k = 0; k < 3; ++k)
          rgb[k] = static_cast<std::uint8_t>(std::lround(std::clamp(sum_c[k] / pixels, 0.0, 1.0) * 255.0));
        cloud.colors.push_back(rgb);
      }
  }
  std::size_t dropped = 0;
  const std::size_t fused = cloud.size();
  if (o.max_color_difference > 0) {
    std::vector<const DepthMap*> depths;
    for (const auto& m : maps) depths.push_back(&m.depth);
    dropped = drop_color_disagreeing_points(cloud, cameras, images, depths, o.max_color_difference,
                                            o.color_visibility_margin);
  }
  if (stats) *stats = {fused, dropped};
  return cloud;
}

std::size_t drop_color_disagreeing_points(PointCloud& cloud, const std::vector<const Camera*>& cameras,
                                          const std::vector<const Image*>& images,
                                          const std::vector<const DepthMap*>& depths, double max_difference,
                                          double visibility_margin) {
  if (!(max_difference > 0) || cloud.empty()) return 0;
  const std::size_t n = cameras.size();
  if (images.size() != n || depths.size() != n)
    fail("colour test: {} cameras, {} images and {} depth maps", n, images.size(), depths.size());
  if (cloud.colors.size() != cloud.size()) fail("colour test: the cloud has no colour per point");
  // The images blurred (5x5 Gaussian, sigma 1 px), as three channels.
  std::vector<cv::Mat> blurred(n);
  for (std::size_t i = 0; i < n; ++i) {
    const Image& img = *images[i];
    const Camera& c = *cameras[i];
    if (img.width != c.width || img.height != c.height || depths[i]->width != c.width ||
        depths[i]->height != c.height)
      fail("colour test: {}: image and depth map must have the camera's size {}x{}", c.image_name, c.width, c.height);
    cv::Mat rgb(img.height, img.width, CV_32FC3);
    for (int y = 0; y < img.height; ++y)
      for (int x = 0; x < img.width; ++x)
        for (int k = 0; k < 3; ++k) rgb.at<cv::Vec3f>(y, x)[k] = img.at(x, y, std::min(k, img.channels - 1));
    cv::GaussianBlur(rgb, blurred[i], cv::Size(5, 5), 1.0, 1.0, cv::BORDER_REFLECT_101);
  }
  std::vector<std::uint8_t> drop(cloud.size(), 0);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t k = 0; k < static_cast<std::ptrdiff_t>(cloud.size()); ++k) {
    const auto pk = static_cast<std::size_t>(k);
    const glm::dvec3 X(cloud.positions[pk]);
    glm::dvec3 colour;
    for (int ch = 0; ch < 3; ++ch) colour[ch] = cloud.colors[pk][ch] / 255.0;
    for (std::size_t i = 0; i < n && !drop[pk]; ++i) {
      const Camera& c = *cameras[i];
      const glm::dvec3 q = c.R_world_to_cam * X + c.t_world_to_cam;
      if (!(q.z > 0.0)) continue;
      const double u = c.fx * q.x / q.z + c.cx, v = c.fy * q.y / q.z + c.cy;
      if (!(u >= 0.0 && v >= 0.0 && u < c.width && v < c.height)) continue;
      const int x = static_cast<int>(u), y = static_cast<int>(v);
      const double d = depths[i]->at(x, y);
      if (d > 0.0 && q.z > visibility_margin * d) continue;  // hidden behind this view's surface
      const cv::Vec3f& b = blurred[i].at<cv::Vec3f>(y, x);
      const double diff = (std::abs(b[0] - colour[0]) + std::abs(b[1] - colour[1]) + std::abs(b[2] - colour[2])) / 3.0;
      if (diff > max_difference) drop[pk] = 1;
    }
  }
  std::vector<std::size_t> kept;
  for (std::size_t k = 0; k < cloud.size(); ++k)
    if (!drop[k]) kept.push_back(k);
  const std::size_t dropped = cloud.size() - kept.size();
  cloud = select_points(cloud, kept);
  return dropped;
}

}  // namespace d2gs
