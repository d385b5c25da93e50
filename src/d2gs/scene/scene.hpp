#pragma once
// Scene loading: COLMAP sparse/0 (binary or text), LLFF poses_bounds.npy, Blender transforms_*.json.
// A Scene holds metadata only (cameras, image paths and sizes, the dataset's own SfM points); images are
// decoded on demand by load_image(), so a command touches only the views it uses.
#include <filesystem>
#include <string>
#include <vector>

#include <glm/glm.hpp>

#include "d2gs/core/image.hpp"
#include "d2gs/scene/camera.hpp"
#include "d2gs/scene/point_cloud.hpp"

namespace d2gs {

enum class SceneFormat { Colmap, Llff, Blender };
const char* to_string(SceneFormat format);

struct SceneLoadOptions {
  int resolution = 1;                  // -r: 1, 2, 4 or 8 (1/R of full resolution)
  glm::vec3 background{0.0f};          // RGBA images are composited on this colour
};

struct Scene {
  std::filesystem::path root;
  SceneFormat format = SceneFormat::Colmap;
  std::string images_folder;           // folder the images are read from, relative to root
  int resolution = 1;
  glm::vec3 background{0.0f};
  std::vector<Camera> cameras;         // global image index = position in this list
  // Blender only: the dataset's own split (global indices); empty for COLMAP/LLFF.
  std::vector<int> dataset_train;
  std::vector<int> dataset_test;
  // The dataset's points3D (triangulated from ALL views, including test views: an oracle).
  PointCloud sfm_points;
  std::vector<std::string> warnings;   // non-fatal problems met while loading (also logged)
};

// Detects the format of `root` and loads it. Throws d2gs::Error naming the file and the problem.
Scene load_scene(const std::filesystem::path& root, const SceneLoadOptions& options = {});
// Decodes camera `index`'s image at the scene's resolution: RGB float [0,1], alpha composited on the
// scene's background, area-resampled when needed; throws if its size differs from the camera's.
Image load_image(const Scene& scene, int index);

}  // namespace d2gs
