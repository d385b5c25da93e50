#pragma once
// Helpers for the scene tests: paths of the real scenes, scratch copies of them (small files copied,
// image folders symlinked), error-message checks and projection.
#include <filesystem>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <string>

#include <gtest/gtest.h>

#include "d2gs/scene/scene.hpp"
#include <glm/glm.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/scene/camera.hpp"
#include "test_paths.hpp"

namespace d2gs::test {

namespace fs = std::filesystem;

// Load options at resolution 1/r.
inline SceneLoadOptions res(int r) {
  SceneLoadOptions o;
  o.resolution = r;
  return o;
}

inline fs::path fern_dir() { return shared_data() / "nerf_llff_data" / "fern"; }
inline fs::path room_dir() { return shared_data() / "llff_nex_reprocessed" / "room"; }
inline fs::path lego_dir() { return shared_data() / "nerf_synthetic" / "lego"; }

inline void write_bytes(const fs::path& path, const std::string& bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  ASSERT_TRUE(out.good()) << path;
}

// <dir>/room: sparse/0/{cameras,images,points3D}.bin copied (so tests may damage them), images/ linked.
inline fs::path make_room_copy(const fs::path& dir) {
  const auto root = dir / "room";
  fs::create_directories(root / "sparse" / "0");
  for (const char* f : {"cameras.bin", "images.bin", "points3D.bin"})
    fs::copy_file(room_dir() / "sparse" / "0" / f, root / "sparse" / "0" / f);
  fs::create_directory_symlink(room_dir() / "images", root / "images");
  return root;
}

// <dir>/fern: poses_bounds.npy and sparse/0/points3D.bin copied, the given image folders linked.
inline fs::path make_fern_copy(const fs::path& dir, std::initializer_list<const char*> folders = {"images_8", "images_4"}) {
  const auto root = dir / "fern";
  fs::create_directories(root / "sparse" / "0");
  fs::copy_file(fern_dir() / "poses_bounds.npy", root / "poses_bounds.npy");
  fs::copy_file(fern_dir() / "sparse" / "0" / "points3D.bin", root / "sparse" / "0" / "points3D.bin");
  for (const char* f : folders) fs::create_directory_symlink(fern_dir() / f, root / f);
  return root;
}

// Runs `f`, expects a d2gs::Error whose message is one line containing every fragment.
inline void expect_error(const std::function<void()>& f, std::initializer_list<std::string> fragments) {
  try {
    f();
    ADD_FAILURE() << "no d2gs::Error thrown (expected one mentioning '" << *fragments.begin() << "')";
  } catch (const d2gs::Error& e) {
    const std::string msg = e.what();
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
    for (const auto& frag : fragments) EXPECT_NE(msg.find(frag), std::string::npos) << "'" << frag << "' not in: " << msg;
  }
}

inline glm::dvec3 to_camera(const Camera& c, const glm::dvec3& world) { return c.R_world_to_cam * world + c.t_world_to_cam; }
inline glm::dvec2 project(const Camera& c, const glm::dvec3& world) {
  const auto x = to_camera(c, world);
  return {c.fx * x.x / x.z + c.cx, c.fy * x.y / x.z + c.cy};
}
inline bool inside(const Camera& c, const glm::dvec2& p) { return p.x >= 0 && p.y >= 0 && p.x < c.width && p.y < c.height; }

}  // namespace d2gs::test
