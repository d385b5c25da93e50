#pragma once
// A posed pinhole camera, in COLMAP/OpenCV conventions: camera axes x right, y down, z forward
// (looking along +z); a world point X maps to camera coordinates R_world_to_cam * X + t_world_to_cam;
// pixel centres are at integer + 0.5 with (0,0) the top-left corner of the top-left pixel, so a
// camera-space point projects to (fx * x/z + cx, fy * y/z + cy).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>

#include <fmt/format.h>
#include <glm/glm.hpp>

namespace d2gs {

struct Camera {
  std::string image_name;           // file name as the dataset names it (e.g. "image000.png", "r_26")
  std::filesystem::path image_path; // file decoded for this camera at the chosen resolution
  int width = 0;                    // image size at the chosen resolution
  int height = 0;
  // When > 1 the file at image_path is larger than (width, height) and is area-resampled on load.
  int resample_factor = 1;
  bool has_alpha = false;           // RGBA source composited on the scene's background on load
  double fx = 0, fy = 0, cx = 0, cy = 0;  // intrinsics at the chosen resolution, in pixels
  glm::dmat3 R_world_to_cam{1.0};
  glm::dvec3 t_world_to_cam{0.0};

  glm::dvec3 center_world() const { return -glm::transpose(R_world_to_cam) * t_world_to_cam; }
  glm::dmat3 R_cam_to_world() const { return glm::transpose(R_world_to_cam); }
  double fov_x() const { return 2.0 * std::atan(0.5 * width / fx); }
  double fov_y() const { return 2.0 * std::atan(0.5 * height / fy); }
};

// Why `c` (intrinsics at its image size, pose) is no pinhole camera of a real scene, or "". Finite values
// can still be impossible, and products of them later overflow or divide by almost zero (a focal of 1e-30
// trained to 5.8 dB "successfully"). The loaders check each camera with it and name the file and the view:
//  - focal lengths from 1 % to 10⁶ times the image size (fields of view below 176° and above 10⁻⁴ degrees);
//  - the principal point within the image widened by its size on every side;
//  - the camera centre within 10⁹ units of the origin;
//  - a rotation (determinant +1), not a reflection.
inline std::string implausible_camera(const Camera& c) {
  const double size = std::max(c.width, c.height);
  for (const double f : {c.fx, c.fy})
    if (!(f >= 0.01 * size && f <= 1e6 * size))
      return fmt::format("focal length {} for a {}×{} image is no pinhole camera's (expected {} to {} pixels)", f,
                         c.width, c.height, 0.01 * size, 1e6 * size);
  if (!(std::abs(c.cx - 0.5 * c.width) <= 1.5 * c.width && std::abs(c.cy - 0.5 * c.height) <= 1.5 * c.height))
    return fmt::format("principal point ({}, {}) lies far outside the {}×{} image", c.cx, c.cy, c.width, c.height);
  const glm::dvec3 centre = c.center_world();
  for (int i = 0; i < 3; ++i)
    if (!(std::abs(centre[i]) <= 1e9))
      return fmt::format("camera centre ({}, {}, {}) is beyond 10⁹ units, no scene's", centre.x, centre.y, centre.z);
  if (!(glm::determinant(c.R_world_to_cam) > 0.0)) return "the rotation is a reflection (determinant −1)";
  return "";
}

}  // namespace d2gs
