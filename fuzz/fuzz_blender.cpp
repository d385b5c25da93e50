// libFuzzer target: a Blender `transforms_*.json` on arbitrary bytes. Any input must either parse or throw
// d2gs::Error; a parsed file has a field of view in (0, pi) and finite, orthonormal camera rotations.
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <numbers>
#include <string_view>

#include "d2gs/core/error.hpp"
#include "d2gs/scene/blender.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const std::string_view text(reinterpret_cast<const char*>(data), size);
  try {
    const d2gs::BlenderTransforms t = d2gs::parse_blender_transforms(text, "transforms_train.json");
    if (!(t.camera_angle_x > 0 && t.camera_angle_x < std::numbers::pi)) std::abort();
    for (const auto& f : t.frames) {
      if (f.file_path.empty()) std::abort();
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(f.center[c])) std::abort();
        if (std::abs(glm::length(f.R_world_to_cam[c]) - 1.0) > 1e-2) std::abort();
      }
    }
  } catch (const d2gs::Error&) {
  }
  return 0;
}
