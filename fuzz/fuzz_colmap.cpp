// libFuzzer target: the COLMAP model parsers (binary and text) on arbitrary bytes. Any input must either
// parse or throw d2gs::Error. A binary file that parses is consumed to its last byte, so writing the
// parsed records back must reproduce the input exactly.
#include <cstdint>
#include <cstdlib>
#include <string>
#include <string_view>

#include "d2gs/core/error.hpp"
#include "d2gs/scene/colmap.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view bytes(reinterpret_cast<const char*>(data), size);
  try {
    const auto cameras = d2gs::parse_colmap_cameras_bin(bytes, "cameras.bin");
    if (d2gs::colmap_cameras_bin(cameras) != bytes) std::abort();
  } catch (const d2gs::Error&) {
  }
  try {
    const auto images = d2gs::parse_colmap_images_bin(bytes, "images.bin");
    for (const auto& im : images)
      if (im.xys.size() != im.point3D_ids.size()) std::abort();
    if (d2gs::colmap_images_bin(images) != bytes) std::abort();
  } catch (const d2gs::Error&) {
  }
  try {
    const auto points = d2gs::parse_colmap_points3D_bin(bytes, "points3D.bin");
    if (d2gs::colmap_points3D_bin(points) != bytes) std::abort();
    const auto cloud = d2gs::colmap_point_cloud(points, "points3D.bin");
    if (cloud.positions.size() != points.size() || cloud.colors.size() != points.size()) std::abort();
  } catch (const d2gs::Error&) {
  }
  // Text parsers: whatever parses must survive a write/parse round trip with the same record count.
  try {
    const auto cameras = d2gs::parse_colmap_cameras_txt(bytes, "cameras.txt");
    if (d2gs::parse_colmap_cameras_txt(d2gs::colmap_cameras_txt(cameras), "rt").size() != cameras.size()) std::abort();
  } catch (const d2gs::Error&) {
  }
  try {
    const auto images = d2gs::parse_colmap_images_txt(bytes, "images.txt");
    (void)images;
  } catch (const d2gs::Error&) {
  }
  try {
    const auto points = d2gs::parse_colmap_points3D_txt(bytes, "points3D.txt");
    if (d2gs::parse_colmap_points3D_txt(d2gs::colmap_points3D_txt(points), "rt").size() != points.size()) std::abort();
  } catch (const d2gs::Error&) {
  }
  return 0;
}
