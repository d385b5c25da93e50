#pragma once
// Blender (NeRF synthetic) scenes: transforms_train.json and transforms_test.json
// (conventions in docs/formats.md, "Scenes").
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include <glm/glm.hpp>

#include "d2gs/scene/scene.hpp"

namespace d2gs {

struct BlenderFrame {
  std::string file_path;           // as written in the JSON, e.g. "./train/r_0"
  glm::dmat3 R_world_to_cam{1.0};  // OpenCV axes (x right, y down, z forward)
  glm::dvec3 center{0.0};          // camera centre in world coordinates
};

struct BlenderTransforms {
  double camera_angle_x = 0;
  std::vector<BlenderFrame> frames;
};

// Parses one transforms_*.json: camera_angle_x and per frame file_path and transform_matrix
// (camera-to-world, OpenGL axes x right, y up, z back; its y and z columns are negated to get OpenCV
// axes). Throws naming `source` and the frame on malformed or non-finite input.
BlenderTransforms parse_blender_transforms(std::string_view json_text, const std::filesystem::path& source);

// Loads train frames then test frames (frames whose image file is missing are skipped with one warning
// per JSON file) and fills Scene::dataset_train / dataset_test.
Scene load_blender_scene(const std::filesystem::path& root, const SceneLoadOptions& options);

}  // namespace d2gs
