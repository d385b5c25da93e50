#include "d2gs/train/view_map.hpp"

#include <algorithm>
#include <cmath>
#include <string>

#include "d2gs/core/error.hpp"
#include "d2gs/core/npy.hpp"

namespace d2gs {

Image read_view_map(const std::filesystem::path& dir, const Camera& cam, const ViewMapRead& read) {
  namespace fs = std::filesystem;
  const fs::path npy = dir / (fs::path(cam.image_name).stem().string() + ".npy");
  if (!fs::exists(npy)) fail_file(npy, "{} missing for training view {}", read.what, cam.image_name);
  const NpyArray a = read_npy(npy);
  if (a.shape.size() != 2) fail_file(npy, "expected an H×W {}, got {} dimensions", read.shape, a.shape.size());
  Image map(static_cast<int>(a.shape[1]), static_cast<int>(a.shape[0]), 1);
  std::size_t usable = 0;
  for (std::size_t i = 0; i < a.values.size(); ++i) {
    const double v = a.values[i];
    if (read.check_depths && (!std::isfinite(v) || v < 0.0))
      fail_file(npy, "depth {} at pixel {} is not a depth (≥ 0, 0 = none)", v, i);
    if (!std::isfinite(v)) fail_file(npy, "value {} at pixel {} is not a finite number", v, i);
    map.pixels[i] = static_cast<float>(v);
    if (!read.zero_is_none || v > 0.0) ++usable;
  }
  // A map without a value would leave the regulariser nothing to act on, silently.
  if (usable == 0)
    fail_file(npy, "holds no value for training view {} ({})", cam.image_name,
              a.values.empty() ? "it is empty" : "every pixel is 0, which means none, or below");
  // Another size is resized, but only by one factor for both axes: another aspect ratio is not this view's map.
  const double sx = static_cast<double>(map.width) / cam.width, sy = static_cast<double>(map.height) / cam.height;
  if (std::abs(sx - sy) > 0.02 * std::max(sx, sy))
    fail_file(npy, "is {}×{}, training view {} is {}×{}: another aspect ratio, so not this view's {}", map.width,
              map.height, cam.image_name, cam.width, cam.height, read.shape);
  if (map.width != cam.width || map.height != cam.height)
    map = read.zero_is_none ? resize_area_nonzero(map, cam.width, cam.height) : resize_area(map, cam.width, cam.height);
  return map;
}

}  // namespace d2gs
