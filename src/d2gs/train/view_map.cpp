#include "d2gs/train/view_map.hpp"

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
  for (std::size_t i = 0; i < a.values.size(); ++i) {
    const double v = a.values[i];
    if (read.check_depths && (!std::isfinite(v) || v < 0.0))
      fail_file(npy, "depth {} at pixel {} is not a depth (≥ 0, 0 = none)", v, i);
    map.pixels[i] = static_cast<float>(v);
  }
  if (map.width != cam.width || map.height != cam.height)
    map = read.zero_is_none ? resize_area_nonzero(map, cam.width, cam.height) : resize_area(map, cam.width, cam.height);
  return map;
}

}  // namespace d2gs
