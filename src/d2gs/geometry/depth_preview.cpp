#include "d2gs/geometry/depth_preview.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/imgproc.hpp>

namespace d2gs {

std::pair<double, double> inverse_depth_range(const std::vector<DepthMap>& maps) {
  std::vector<float> inv;
  for (const auto& m : maps)
    for (float z : m.depth)
      if (z > 0.0f) inv.push_back(1.0f / z);
  if (inv.empty()) return {0.0, 0.0};
  const auto at = [&](double q) {
    const auto k = static_cast<std::size_t>(q * static_cast<double>(inv.size() - 1));
    std::nth_element(inv.begin(), inv.begin() + static_cast<std::ptrdiff_t>(k), inv.end());
    return static_cast<double>(inv[k]);
  };
  const double lo = at(0.02), hi = at(0.98);
  return {lo, hi};
}

Image depth_preview(const DepthMap& map, std::pair<double, double> range) {
  const auto [lo, hi] = range;
  const double span = hi > lo ? hi - lo : 1.0;
  cv::Mat level(map.height, map.width, CV_8UC1);
  for (int y = 0; y < map.height; ++y)
    for (int x = 0; x < map.width; ++x) {
      const float z = map.at(x, y);
      const double t = z > 0.0f ? std::clamp((1.0 / z - lo) / span, 0.0, 1.0) : 0.0;
      level.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(std::lround(t * 255.0));
    }
  cv::Mat bgr;
  cv::applyColorMap(level, bgr, cv::COLORMAP_TURBO);
  Image out(map.width, map.height, 3);
  for (int y = 0; y < map.height; ++y)
    for (int x = 0; x < map.width; ++x) {
      if (!(map.at(x, y) > 0.0f)) continue;  // black
      const cv::Vec3b c = bgr.at<cv::Vec3b>(y, x);
      for (int k = 0; k < 3; ++k) out.at(x, y, k) = static_cast<float>(c[2 - k]) / 255.0f;
    }
  return out;
}

}  // namespace d2gs
