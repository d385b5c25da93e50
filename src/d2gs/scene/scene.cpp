#include "d2gs/scene/scene.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <string>
#include <vector>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/resize_pil.hpp"
#include "d2gs/scene/blender.hpp"
#include "d2gs/scene/colmap.hpp"
#include "d2gs/scene/llff.hpp"
#include "d2gs/scene/split.hpp"

namespace d2gs {
namespace fs = std::filesystem;

namespace {

bool is_dir(const fs::path& p) {
  std::error_code ec;
  return fs::is_directory(p, ec);
}
// Whether the marker file of a layout is present. A marker that exists but is no regular file (a named
// pipe, a folder, a loop of symbolic links) is an error saying so, not a reason to try the next layout.
bool has_marker(const fs::path& p) {
  std::error_code ec;
  if (fs::status(p, ec).type() == fs::file_type::not_found) return false;
  require_regular_file(p);
  return true;
}

std::string folder_name(int factor) { return factor == 1 ? std::string("images") : fmt::format("images_{}", factor); }

// PNG colour types 4 (grey + alpha) and 6 (RGBA) carry an alpha channel; byte 25 of the file.
bool png_has_alpha(const fs::path& path) {
  require_regular_file(path);  // a named pipe would block the open
  std::ifstream in(path, std::ios::binary);
  unsigned char head[26] = {};
  in.read(reinterpret_cast<char*>(head), sizeof head);
  if (in.gcount() != static_cast<std::streamsize>(sizeof head)) return false;
  static constexpr unsigned char magic[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (!std::equal(magic, magic + 8, head)) return false;
  return head[25] == 4 || head[25] == 6;
}

}  // namespace

const char* to_string(SceneFormat format) {
  switch (format) {
    case SceneFormat::Colmap: return "colmap";
    case SceneFormat::Llff: return "llff";
    case SceneFormat::Blender: return "blender";
  }
  return "unknown";
}

void check_resolution(int resolution) {
  if (resolution != 1 && resolution != 2 && resolution != 4 && resolution != 8)
    fail("resolution (-r) must be 1, 2, 4 or 8, got {}", resolution);
}

const char* to_string(ImageSource source) { return source == ImageSource::Largest ? "largest" : "folder"; }

ImageSource image_source_from_string(const std::string& s) {
  if (s == "folder") return ImageSource::Folder;
  if (s == "largest") return ImageSource::Largest;
  fail("image source '{}' is not one of folder, largest", s);
}

ImageFolderChoice choose_image_folder(const fs::path& root, int resolution, ImageSource source) {
  check_resolution(resolution);
  std::vector<int> factors;  // every F dividing R: R, R/2, ..., 1 (Folder) or 1, 2, ..., R (Largest)
  for (int f = resolution; f >= 1; f /= 2) factors.push_back(f);
  if (source == ImageSource::Largest) std::reverse(factors.begin(), factors.end());
  std::string looked;
  for (int f : factors) {
    const auto name = folder_name(f);
    if (is_dir(root / name)) return {name, f, resolution / f};
    looked += fmt::format("{}{}/", looked.empty() ? "" : ", ", name);
  }
  std::string present;
  for (int f : {1, 2, 4, 8, 16})
    if (is_dir(root / folder_name(f))) present += fmt::format("{}{}/", present.empty() ? "" : ", ", folder_name(f));
  if (present.empty())
    fail_file(root, "no image folder for -r {}: looked for {}", resolution, looked);
  fail_file(root, "no image folder for -r {}: looked for {} (present: {}; images are only ever downsampled)",
            resolution, looked, present);
}

int resampled_length(int length, int factor) {
  if (factor <= 1) return length;
  return static_cast<int>(std::max(1L, round_half_even(static_cast<double>(length) / factor)));
}

void set_camera_image(Camera& camera, int resample) {
  const ImageSize size = read_image_size(camera.image_path);
  camera.resample_factor = std::max(1, resample);
  camera.width = resampled_length(size.width, camera.resample_factor);
  camera.height = resampled_length(size.height, camera.resample_factor);
  camera.has_alpha = png_has_alpha(camera.image_path);
}

Scene empty_scene(const fs::path& root, SceneFormat format, const SceneLoadOptions& options) {
  Scene scene;
  scene.root = root;
  scene.format = format;
  scene.resolution = options.resolution;
  scene.background = options.background;
  scene.image_source = options.image_source;
  return scene;
}

Scene load_scene(const fs::path& root, const SceneLoadOptions& options) {
  check_resolution(options.resolution);
  for (int c = 0; c < 3; ++c)
    if (!std::isfinite(options.background[c]) || options.background[c] < 0 || options.background[c] > 1)
      fail("background colour components must lie in [0, 1]");
  if (!is_dir(root)) {
    std::error_code ec;
    const fs::file_status st = fs::status(root, ec);
    if (st.type() == fs::file_type::not_found) fail_file(root, "scene folder not found");
    if (ec) fail_file(root, "cannot open the scene folder: {}", ec.message());  // e.g. a loop of symbolic links
    fail_file(root, "is a file, not a scene folder (-s takes the folder that holds sparse/0, poses_bounds.npy or "
                    "transforms_train.json)");
  }
  const fs::path sparse = root / "sparse" / "0";
  if (has_marker(sparse / "images.bin") || has_marker(sparse / "images.txt")) return load_colmap_scene(root, options);
  if (has_marker(root / "poses_bounds.npy")) return load_llff_scene(root, options);
  if (has_marker(root / "transforms_train.json")) return load_blender_scene(root, options);
  fail_file(root,
            "unknown scene format: looked for sparse/0/images.bin or sparse/0/images.txt (COLMAP), "
            "poses_bounds.npy (LLFF) and transforms_train.json (Blender)");
}

Image load_image(const Scene& scene, int index) {
  if (index < 0 || static_cast<std::size_t>(index) >= scene.cameras.size())
    fail_file(scene.root, "image index {} is out of range (the scene has {} images)", index, scene.cameras.size());
  const Camera& cam = scene.cameras[static_cast<std::size_t>(index)];
  const Image src = read_image(cam.image_path);
  const int f = std::max(1, cam.resample_factor);
  if (resampled_length(src.width, f) != cam.width || resampled_length(src.height, f) != cam.height) {
    if (f == 1) fail_file(cam.image_path, "image is {}x{}, expected {}x{}", src.width, src.height, cam.width, cam.height);
    fail_file(cam.image_path, "image is {}x{}, expected a size giving {}x{} after 1/{} resampling", src.width,
              src.height, cam.width, cam.height, f);
  }
  // To RGB, alpha composited on the background (before resampling, as the 3DGS loader does).
  Image rgb(src.width, src.height, 3);
  const std::size_t n = static_cast<std::size_t>(src.width) * src.height;
  const int c = src.channels;
  for (std::size_t i = 0; i < n; ++i) {
    const float* p = src.pixels.data() + i * c;
    float* q = rgb.pixels.data() + i * 3;
    if (c == 1 || c == 2) {
      q[0] = q[1] = q[2] = p[0];
    } else {
      q[0] = p[0], q[1] = p[1], q[2] = p[2];
    }
    if (c == 2 || c == 4) {
      const float a = p[c - 1];
      for (int k = 0; k < 3; ++k) q[k] = q[k] * a + scene.background[k] * (1.0f - a);
    }
  }
  if (f == 1) return rgb;
  if (scene.image_source == ImageSource::Largest) return resize_pil_bicubic(rgb, cam.width, cam.height);
  return resize_area(rgb, cam.width, cam.height);
}

}  // namespace d2gs
