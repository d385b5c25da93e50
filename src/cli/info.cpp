// d2gs info: the backend --device auto would use; with -s, a scene's metadata (no image is decoded), its
// cameras and split.
#include <algorithm>
#include <cstdio>
#include <memory>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <nlohmann/json.hpp>

#include "cli/commands.hpp"
#include "cli/scene_flags.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/render/cpu/composite_tiles.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/device_choice.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"

namespace d2gs::cli {
namespace {

struct InfoOptions {
  SceneFlags scene;
  bool json = false;
};

std::string join(const std::vector<int>& v) {
  std::string s;
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (i) s += " ";
    s += std::to_string(v[i]);
  }
  return s;
}

nlohmann::ordered_json to_json(const Scene& scene, const Split& split) {
  using json = nlohmann::ordered_json;
  json cams = json::array();
  for (std::size_t i = 0; i < scene.cameras.size(); ++i) {
    const Camera& c = scene.cameras[i];
    json R = json::array();
    for (int r = 0; r < 3; ++r) R.push_back({c.R_world_to_cam[0][r], c.R_world_to_cam[1][r], c.R_world_to_cam[2][r]});
    const auto centre = c.center_world();
    cams.push_back({{"index", i},
                    {"name", c.image_name},
                    {"path", c.image_path.string()},
                    {"width", c.width},
                    {"height", c.height},
                    {"resample_factor", c.resample_factor},
                    {"has_alpha", c.has_alpha},
                    {"fx", c.fx},
                    {"fy", c.fy},
                    {"cx", c.cx},
                    {"cy", c.cy},
                    {"R_world_to_cam", R},
                    {"t_world_to_cam", {c.t_world_to_cam.x, c.t_world_to_cam.y, c.t_world_to_cam.z}},
                    {"center", {centre.x, centre.y, centre.z}}});
  }
  json out;
  out["format"] = to_string(scene.format);
  out["root"] = scene.root.string();
  out["images_folder"] = scene.images_folder;
  out["resolution"] = scene.resolution;
  out["background"] = {scene.background.x, scene.background.y, scene.background.z};
  out["cameras"] = std::move(cams);
  out["train"] = split.train;
  out["test"] = split.test;
  if (scene.format == SceneFormat::Blender) {
    out["dataset_train"] = scene.dataset_train;
    out["dataset_test"] = scene.dataset_test;
  }
  out["points"] = scene.sfm_points.size();
  out["warnings"] = scene.warnings;
  return out;
}

void print_table(const Scene& scene, const Split& split) {
  std::string s;
  s += fmt::format("scene       {}\n", scene.root.string());
  s += fmt::format("format      {}\n", to_string(scene.format));
  s += fmt::format("images      {} (resolution 1/{})\n", scene.images_folder, scene.resolution);
  s += fmt::format("cameras     {}\n", scene.cameras.size());
  s += fmt::format("{:<12}{}\n", fmt::format("train ({})", split.train.size()), join(split.train));
  s += fmt::format("{:<12}{}\n", fmt::format("test ({})", split.test.size()), join(split.test));
  s += fmt::format("points      {}{}\n", scene.sfm_points.size(),
                   scene.sfm_points.empty() ? "" : " (dataset points3D, triangulated from all views: oracle only)");
  s += fmt::format("\n{:>5}  {:<16} {:>11} {:>10} {:>10} {:>9} {:>9}  {:<5}  {}\n", "index", "name", "size", "fx", "fy",
                   "cx", "cy", "split", "centre");
  for (std::size_t i = 0; i < scene.cameras.size(); ++i) {
    const Camera& c = scene.cameras[i];
    const int idx = static_cast<int>(i);
    const char* role = std::find(split.train.begin(), split.train.end(), idx) != split.train.end()  ? "train"
                       : std::find(split.test.begin(), split.test.end(), idx) != split.test.end() ? "test"
                                                                                                  : "-";
    const auto centre = c.center_world();
    s += fmt::format("{:>5}  {:<16} {:>11} {:>10.3f} {:>10.3f} {:>9.3f} {:>9.3f}  {:<5}  ({:.4f}, {:.4f}, {:.4f})\n", i,
                     c.image_name, fmt::format("{}x{}", c.width, c.height), c.fx, c.fy, c.cx, c.cy, role, centre.x,
                     centre.y, centre.z);
  }
  if (!scene.warnings.empty()) {
    s += "\nwarnings:\n";
    for (const auto& w : scene.warnings) s += "  " + w + "\n";
  }
  std::fputs(s.c_str(), stdout);
}

// The backends: what --device auto would use and why, the CPU's tile-loop levels, CUDA's state.
nlohmann::ordered_json backend_json() {
  const render::DeviceChoice choice = render::choose_device(render::DeviceRequest::Auto, render::DeviceWork::Train);
  const render::DeviceChoice rendering =
      render::choose_device(render::DeviceRequest::Auto, render::DeviceWork::Render);
  nlohmann::ordered_json j;
  j["device"] = render::to_string(choice.device);  // d2gs train
  j["description"] = choice.description;
  if (!choice.reason.empty()) j["reason"] = choice.reason;
  j["render_device"] = render::to_string(rendering.device);  // d2gs render, eval
  if (!rendering.reason.empty()) j["render_reason"] = rendering.reason;
  j["cpu_tile_levels"] = render::cpu::available_tile_isas();
  j["cuda_devices"] = cuda::device_count();
  j["cuda_device"] = cuda::describe_device();
  return j;
}

void print_backend() {
  const render::DeviceChoice choice = render::choose_device(render::DeviceRequest::Auto, render::DeviceWork::Train);
  const render::DeviceChoice rendering =
      render::choose_device(render::DeviceRequest::Auto, render::DeviceWork::Render);
  std::string s;
  s += fmt::format("device      {} (what --device auto uses for training)\n", choice.description);
  if (!choice.reason.empty()) s += fmt::format("            not CUDA: {}\n", choice.reason);
  s += fmt::format("rendering   {} (d2gs render and eval with --device auto)\n", rendering.description);
  s += fmt::format("CPU levels  {} (D2GS_CPU_ISA picks one)\n", fmt::join(render::cpu::available_tile_isas(), ", "));
  s += fmt::format("CUDA        {} device(s): {}\n", cuda::device_count(), cuda::describe_device());
  std::fputs(s.c_str(), stdout);
}

}  // namespace

Run add_info_command(CLI::App& app) {
  auto opts = std::make_shared<InfoOptions>();
  auto* sub = app.add_subcommand(
      "info", "Print the backend d2gs would use (--device auto) and, with -s, a scene's format, cameras, sparse-view "
              "split and point count");
  add_scene_flags(*sub, opts->scene, SplitFlags::All);
  sub->get_option("--source")->required(false);
  sub->add_flag("--json", opts->json, "Machine-readable output");
  return [opts]() -> int {
    if (opts->scene.source.empty()) {
      if (opts->json) std::fputs((nlohmann::ordered_json{{"backend", backend_json()}}.dump(2) + "\n").c_str(), stdout);
      else print_backend();
      return 0;
    }
    const auto [scene, split] = opts->scene.load();
    if (opts->json) {
      nlohmann::ordered_json j = to_json(scene, split);
      j["backend"] = backend_json();
      const std::string text = j.dump(2, ' ', false, nlohmann::ordered_json::error_handler_t::replace) + "\n";
      std::fputs(text.c_str(), stdout);
    } else {
      print_table(scene, split);
      std::fputs("\n", stdout);
      print_backend();
    }
    return 0;
  };
}

}  // namespace d2gs::cli
