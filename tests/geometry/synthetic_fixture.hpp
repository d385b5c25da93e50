#pragma once
// What the geometry tests share: the small synthetic scene (252x189, exact depth), the same scene written
// once per test process as an LLFF folder, and a recorder of decoded image files (the no-test-view rule).
#include <unistd.h>

#include <filesystem>
#include <vector>

#include <fmt/format.h>

#include "d2gs/core/image.hpp"
#include "d2gs/demo/synthetic_scene.hpp"

namespace d2gs::test {

inline SyntheticSceneOptions small_synthetic_options() {
  SyntheticSceneOptions o;
  o.width = 252;
  o.height = 189;
  o.supersample = 2;
  o.seed = 3;
  return o;
}

inline const SyntheticScene& small_synthetic_scene() {
  static const SyntheticScene s(small_synthetic_options());
  return s;
}

// The small scene written as an LLFF folder (images/, poses_bounds.npy, ...), removed at exit.
inline const std::filesystem::path& small_synthetic_dir() {
  struct Shared {
    std::filesystem::path dir =
        std::filesystem::temp_directory_path() / "d2gs-tests" / fmt::format("geometry-synthetic-{}", ::getpid());
    Shared() {
      std::filesystem::remove_all(dir);
      write_synthetic_scene(dir, small_synthetic_options());
    }
    ~Shared() {
      std::error_code ec;
      std::filesystem::remove_all(dir, ec);
    }
  };
  static const Shared shared;
  return shared.dir;
}

// Records every decoded image file while alive.
struct ImageReads {
  std::vector<std::filesystem::path> paths;
  ImageReads() {
    set_image_read_observer([this](const std::filesystem::path& p) { paths.push_back(p); });
  }
  ~ImageReads() { set_image_read_observer(nullptr); }
  ImageReads(const ImageReads&) = delete;
  ImageReads& operator=(const ImageReads&) = delete;
};

}  // namespace d2gs::test
