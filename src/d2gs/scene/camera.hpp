#pragma once
// A posed pinhole camera, in COLMAP/OpenCV conventions: camera axes x right, y down, z forward
// (looking along +z); a world point X maps to camera coordinates R_world_to_cam * X + t_world_to_cam;
// pixel centres are at integer + 0.5 with (0,0) the top-left corner of the top-left pixel, so a
// camera-space point projects to (fx * x/z + cx, fy * y/z + cy).
#include <cmath>
#include <filesystem>
#include <string>

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

}  // namespace d2gs
