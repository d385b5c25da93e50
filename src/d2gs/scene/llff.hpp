#pragma once
// LLFF scenes: poses_bounds.npy (N x 17) beside images_N/ folders and no COLMAP images file
// (conventions in docs/formats.md, "Scenes", and ../shared/data/SOURCES.md).
#include <filesystem>
#include <vector>

#include <glm/glm.hpp>

#include "d2gs/core/npy.hpp"
#include "d2gs/scene/scene.hpp"

namespace d2gs {

// One row of poses_bounds.npy.
struct LlffPose {
  glm::dmat3 R_world_to_cam{1.0};  // OpenCV axes (x right, y down, z forward)
  glm::dvec3 center{0.0};          // camera centre in world coordinates
  double height = 0, width = 0, focal = 0;  // hwf at full resolution
  double near = 0, far = 0;
};

// Validates the array (N x 17, finite, positive hwf, orthonormal rotation) and converts every row:
// the rotation columns [down, right, back] become the OpenCV camera-to-world [col1, col0, -col2].
// `source` names the file in error messages.
std::vector<LlffPose> parse_llff_poses(const NpyArray& array, const std::filesystem::path& source);

// Loads <root>/poses_bounds.npy, the images of the folder chosen for the resolution (sorted by name,
// one per row) and, when present, <root>/sparse/0/points3D.{bin,txt} as the oracle cloud.
Scene load_llff_scene(const std::filesystem::path& root, const SceneLoadOptions& options);

}  // namespace d2gs
