#include "d2gs/scene/llff.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <string>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "d2gs/core/error.hpp"
#include "d2gs/scene/colmap.hpp"

namespace d2gs {
namespace fs = std::filesystem;

namespace {

bool is_image_file(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg";
}

// Regular image files (png/jpg/jpeg, any case) of `dir`, sorted by file name. Hidden files (a name
// starting with '.': interrupted atomic writes, macOS "._" metadata) are not images of the scene.
std::vector<std::string> list_images(const fs::path& dir) {
  std::vector<std::string> names;
  std::error_code ec;
  for (fs::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec))
    if (it->is_regular_file(ec) && is_image_file(it->path()) && !it->path().filename().string().starts_with('.'))
      names.push_back(it->path().filename().string());
  if (ec) fail_file(dir, "cannot list folder ({})", ec.message());
  std::sort(names.begin(), names.end());
  return names;
}

}  // namespace

std::vector<LlffPose> parse_llff_poses(const NpyArray& array, const fs::path& source) {
  std::string shape;
  for (std::size_t i = 0; i < array.shape.size(); ++i) {
    if (i) shape += "x";
    shape += std::to_string(array.shape[i]);
  }
  if (array.shape.size() != 2 || array.shape[1] != 17)
    fail_file(source, "expected an N x 17 array (3x5 pose + near, far per image), found shape {}",
              shape.empty() ? "()" : shape);
  const std::size_t n = array.shape[0];
  if (n == 0) fail_file(source, "the array has no rows");
  std::vector<LlffPose> poses;
  poses.reserve(n);
  for (std::size_t k = 0; k < n; ++k) {
    const double* v = array.values.data() + k * 17;
    for (int i = 0; i < 17; ++i)
      if (!std::isfinite(v[i])) fail_file(source, "row {} has a non-finite value in column {}", k, i);
    // Row-major 3x5: entry (r, c) = v[r * 5 + c].
    const auto col = [&](int c) { return glm::dvec3(v[c], v[5 + c], v[10 + c]); };
    LlffPose p;
    // OpenCV camera-to-world columns: x = right = col1, y = down = col0, z = forward = -back = -col2.
    const glm::dmat3 c2w(col(1), col(0), -col(2));
    const glm::dmat3 gram = glm::transpose(c2w) * c2w;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (std::abs(gram[i][j] - (i == j ? 1.0 : 0.0)) > 1e-3)
          fail_file(source, "row {}: the rotation is not orthonormal", k);
    p.R_world_to_cam = glm::transpose(c2w);
    p.center = col(3);
    p.height = v[4];
    p.width = v[9];
    p.focal = v[14];
    p.near = v[15];
    p.far = v[16];
    if (p.height <= 0 || p.width <= 0 || p.focal <= 0)
      fail_file(source, "row {}: height, width and focal must be positive, found {}, {}, {}", k,
                p.height, p.width, p.focal);
    poses.push_back(p);
  }
  return poses;
}

Scene load_llff_scene(const fs::path& root, const SceneLoadOptions& options) {
  const fs::path poses_path = root / "poses_bounds.npy";
  const auto poses = parse_llff_poses(read_npy(poses_path), poses_path);

  Scene scene = empty_scene(root, SceneFormat::Llff, options);
  const auto folder = choose_image_folder(root, options.resolution, options.image_source);
  scene.images_folder = folder.folder;
  const auto names = list_images(root / folder.folder);
  if (names.size() != poses.size())
    fail_file(poses_path, "{} rows but {} has {} images (one row per image, in name order)", poses.size(),
              (root / folder.folder).string(), names.size());

  const double r = options.resolution;
  for (std::size_t k = 0; k < poses.size(); ++k) {
    const auto& p = poses[k];
    Camera cam;
    cam.image_name = names[k];
    cam.image_path = root / folder.folder / names[k];
    set_camera_image(cam, folder.resample);
    // LLFF convention: the focal length scales with the resolution factor, the principal point is the
    // image centre of the image actually used.
    cam.fx = cam.fy = p.focal / r;
    cam.cx = 0.5 * cam.width;
    cam.cy = 0.5 * cam.height;
    cam.R_world_to_cam = p.R_world_to_cam;
    cam.t_world_to_cam = -(p.R_world_to_cam * p.center);
    // Finite is not enough (scene/camera.hpp); the row is named, as for the checks of parse_llff_poses.
    if (const std::string why = implausible_camera(cam); !why.empty()) fail_file(poses_path, "row {}: {}", k, why);
    // The focal length is the poses' at 1/R: an image of another size would be trained with wrong intrinsics.
    if (std::abs(cam.width - p.width / r) > 1.0 || std::abs(cam.height - p.height / r) > 1.0)
      fail_file(cam.image_path,
                "image is {}x{} at -r {}, but poses_bounds.npy row {} gives {}x{} at full resolution, i.e. {}x{} at 1/{} "
                "(every image of the scene must have the size of its pose row)",
                cam.width, cam.height, options.resolution, k, p.width, p.height, p.width / r, p.height / r,
                options.resolution);
    scene.cameras.push_back(std::move(cam));
  }

  const fs::path sparse = root / "sparse" / "0";
  if (has_colmap_points3D(sparse)) {
    std::error_code ec;
    const auto points_path = fs::is_regular_file(sparse / "points3D.bin", ec) ? sparse / "points3D.bin" : sparse / "points3D.txt";
    scene.sfm_points = colmap_point_cloud(read_colmap_points3D(sparse), points_path);
  }
  return scene;
}

}  // namespace d2gs
