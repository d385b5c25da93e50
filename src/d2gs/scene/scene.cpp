#include "d2gs/scene/scene.hpp"

#include "d2gs/core/error.hpp"

namespace d2gs {

const char* to_string(SceneFormat format) {
  switch (format) {
    case SceneFormat::Colmap: return "colmap";
    case SceneFormat::Llff: return "llff";
    case SceneFormat::Blender: return "blender";
  }
  return "unknown";
}

Scene load_scene(const std::filesystem::path& root, const SceneLoadOptions&) { fail_file(root, "scene loading not implemented yet"); }
Image load_image(const Scene& scene, int) { fail_file(scene.root, "image loading not implemented yet"); }

}  // namespace d2gs
