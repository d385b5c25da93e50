#include "d2gs/scene/blender.hpp"

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>

#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/json_value.hpp"

namespace d2gs {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

double number_at(const json& j, const fs::path& source, const std::string& where) {
  if (!j.is_number()) fail_file(source, "{} is not a number", where);
  const double v = j.get<double>();
  if (!std::isfinite(v)) fail_file(source, "{} is not finite", where);
  return v;
}

// Image file of a frame: file_path relative to the root, ".png" added when it has no extension.
fs::path frame_image_path(const fs::path& root, const std::string& file_path) {
  fs::path p = root / fs::path(file_path).lexically_normal();
  if (!fs::path(file_path).has_extension()) p += ".png";
  return p;
}

}  // namespace

BlenderTransforms parse_blender_transforms(std::string_view json_text, const fs::path& source) {
  const json doc = parse_json(json_text, source);  // a duplicate key is an error
  if (!doc.is_object()) fail_file(source, "expected a JSON object");
  BlenderTransforms out;
  if (!doc.contains("camera_angle_x")) fail_file(source, "missing camera_angle_x");
  out.camera_angle_x = number_at(doc["camera_angle_x"], source, "camera_angle_x");
  if (out.camera_angle_x <= 0 || out.camera_angle_x >= std::numbers::pi)
    fail_file(source, "camera_angle_x {} is outside (0, pi)", out.camera_angle_x);
  if (!doc.contains("frames") || !doc["frames"].is_array()) fail_file(source, "missing the frames list");
  const auto& frames = doc["frames"];
  out.frames.reserve(frames.size());
  std::map<std::string, std::size_t> first_frame;  // image path (normalised) -> first frame that names it
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const auto& f = frames[k];
    const std::string where = fmt::format("frame {}", k);
    if (!f.is_object() || !f.contains("file_path") || !f["file_path"].is_string())
      fail_file(source, "{} has no file_path string", where);
    BlenderFrame frame;
    frame.file_path = f["file_path"].get<std::string>();
    if (frame.file_path.empty()) fail_file(source, "{} has an empty file_path", where);
    const std::string shown = printable(frame.file_path, 200);  // in messages
    if (const auto [first, fresh] = first_frame.emplace(frame_image_path("", frame.file_path).generic_string(), k);
        !fresh)
      fail_file(source, "{} ({}) names the same image as frame {} ({})", where, shown, first->second,
                printable(out.frames[first->second].file_path, 200));
    if (!f.contains("transform_matrix") || !f["transform_matrix"].is_array())
      fail_file(source, "{} ({}) has no 4x4 transform_matrix", where, shown);
    const auto& m = f["transform_matrix"];
    if (m.size() != 4)
      fail_file(source, "{} ({}): transform_matrix has {} rows, expected 4", where, shown, m.size());
    double a[4][4];
    for (int r = 0; r < 4; ++r) {
      if (!m[r].is_array() || m[r].size() != 4)
        fail_file(source, "{} ({}): transform_matrix row {} does not have 4 entries", where, shown, r);
      for (int c = 0; c < 4; ++c)
        a[r][c] = number_at(m[r][c], source, fmt::format("{} ({}) transform_matrix[{}][{}]", where, shown, r, c));
    }
    // A rigid transform: its last row is [0, 0, 0, 1] (anything else is a projective matrix, or a damaged one).
    for (int c = 0; c < 4; ++c)
      if (std::abs(a[3][c] - (c == 3 ? 1.0 : 0.0)) > 1e-6)
        fail_file(source, "{} ({}): transform_matrix's last row is [{}, {}, {}, {}], expected [0, 0, 0, 1]", where,
                  shown, a[3][0], a[3][1], a[3][2], a[3][3]);
    // Camera-to-world in OpenGL axes (x right, y up, z back): negate the y and z columns for OpenCV.
    glm::dmat3 c2w;
    for (int r = 0; r < 3; ++r) {
      c2w[0][r] = a[r][0];
      c2w[1][r] = -a[r][1];
      c2w[2][r] = -a[r][2];
    }
    const glm::dmat3 gram = glm::transpose(c2w) * c2w;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        if (std::abs(gram[i][j] - (i == j ? 1.0 : 0.0)) > 1e-3)
          fail_file(source, "{} ({}): the rotation of transform_matrix is not orthonormal", where, shown);
    frame.R_world_to_cam = glm::transpose(c2w);
    frame.center = glm::dvec3(a[0][3], a[1][3], a[2][3]);
    out.frames.push_back(std::move(frame));
  }
  return out;
}

Scene load_blender_scene(const fs::path& root, const SceneLoadOptions& options) {
  // Blender has one image folder: the image source changes only the filter.
  Scene scene = empty_scene(root, SceneFormat::Blender, options);

  std::vector<std::string> folders;
  std::map<fs::path, std::string> first_frame;  // image -> the first frame (file and index) that names it
  for (const char* split : {"train", "test"}) {
    const fs::path json_path = root / fmt::format("transforms_{}.json", split);
    std::error_code ec;
    if (!fs::is_regular_file(json_path, ec)) {
      if (std::string_view(split) == "train") fail_file(json_path, "not found");
      const auto msg = fmt::format("{}: not found; the scene has no test views", json_path.string());
      spdlog::warn("{}", msg);
      scene.warnings.push_back(msg);
      continue;
    }
    const auto transforms = parse_blender_transforms(read_file(json_path), json_path);
    // A test frame naming a train frame's image would score the model on a view it trained on.
    for (std::size_t k = 0; k < transforms.frames.size(); ++k) {
      const auto image = frame_image_path(root, transforms.frames[k].file_path);
      if (const auto [first, fresh] = first_frame.emplace(image, fmt::format("{} frame {}", json_path.filename().string(), k));
          !fresh)
        fail_file(json_path, "frame {} ({}) names the same image as {}", k, printable(transforms.frames[k].file_path, 200),
                  first->second);
    }
    std::size_t missing = 0;
    std::string first_missing;
    for (const auto& frame : transforms.frames) {
      Camera cam;
      cam.image_path = frame_image_path(root, frame.file_path);
      cam.image_name = fs::path(frame.file_path).filename().string();
      if (!fs::is_regular_file(cam.image_path, ec)) {
        // Test frames without an image are skipped (lego ships every 8th test image only); a train frame
        // without one would silently move the split, which is computed over the train frames.
        if (std::string_view(split) == "train")
          fail_file(json_path, "train frame {} ({}) has no image file {}: every train frame needs its image",
                    &frame - transforms.frames.data(), frame.file_path, cam.image_path.string());
        if (missing++ == 0) first_missing = cam.image_path.string();
        continue;
      }
      set_camera_image(cam, options.resolution);
      cam.fx = cam.fy = 0.5 * cam.width / std::tan(0.5 * transforms.camera_angle_x);
      cam.cx = 0.5 * cam.width;
      cam.cy = 0.5 * cam.height;
      cam.R_world_to_cam = frame.R_world_to_cam;
      cam.t_world_to_cam = -(frame.R_world_to_cam * frame.center);
      if (const std::string why = implausible_camera(cam); !why.empty())
        fail_file(json_path, "frame {} ({}): {}", &frame - transforms.frames.data(), frame.file_path, why);
      const auto folder = fs::relative(cam.image_path.parent_path(), root, ec).generic_string();
      if (std::find(folders.begin(), folders.end(), folder) == folders.end()) folders.push_back(folder);
      (std::string_view(split) == "train" ? scene.dataset_train : scene.dataset_test)
          .push_back(static_cast<int>(scene.cameras.size()));
      scene.cameras.push_back(std::move(cam));
    }
    if (missing > 0) {
      const auto msg = fmt::format("{}: {} of {} frames have no image file (first: {}); skipped", json_path.string(),
                                   missing, transforms.frames.size(), first_missing);
      spdlog::warn("{}", msg);
      scene.warnings.push_back(msg);
    }
  }
  if (scene.dataset_train.empty()) fail_file(root / "transforms_train.json", "lists no train frame");
  for (std::size_t i = 0; i < folders.size(); ++i) {
    if (i) scene.images_folder += ", ";
    scene.images_folder += folders[i];
  }
  return scene;
}

}  // namespace d2gs
