// d2gs render: renders a trained model (PLY) from the cameras of a scene, one PNG per view.
//   d2gs render --model point_cloud.ply -s SCENE [-r R] [--n-views N] [--split test|train|all] -o DIR
//               [--depth] [--alpha] [--white-background] [--sh-degree D]
// Outputs (docs/rendering.md): DIR/<image stem>.png (RGB clamped to [0,1], 8-bit); with --depth
// DIR/<stem>_depth.npy (float32 H x W, expected view-space depth normalised by alpha, 0 where alpha is
// 0) and DIR/<stem>_depth.png (16-bit, millimetres: round(depth * 1000), saturating at 65.535 units);
// with --alpha DIR/<stem>_alpha.png (8-bit).
#include <algorithm>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cli/commands.hpp"
#include "cli/device_flag.hpp"
#include "cli/scene_flags.hpp"
#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/interrupt.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/image.hpp"
#include "d2gs/core/log.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/render/rasterizer.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"

namespace d2gs::cli {
namespace {

struct RenderCommandOptions {
  std::string model;
  SceneFlags scene;
  std::string output;
  std::string split = "test";
  int sh_degree = -1;
  bool depth = false;
  bool alpha = false;
  std::string device;
};

// The files a view is written to: DIR/<image stem>.png, and with --alpha / --depth the extra maps.
std::vector<std::string> output_names(const std::string& stem, const RenderCommandOptions& o) {
  std::vector<std::string> names = {stem + ".png"};
  if (o.alpha) names.push_back(stem + "_alpha.png");
  if (o.depth) {
    names.push_back(stem + "_depth.npy");
    names.push_back(stem + "_depth.png");
  }
  return names;
}

// Before any rendering: no two views may be written to one file (Blender's train/r_0 and test/r_0, an LLFF
// folder with image018.jpg and image018.png), no file already there is replaced, and the scene's own image
// folders are not written into.
void check_render_outputs(const std::filesystem::path& out_dir, const Scene& scene, const std::vector<int>& views,
                          const RenderCommandOptions& o) {
  namespace fs = std::filesystem;
  std::error_code ec;
  if (fs::exists(out_dir, ec)) {
    // The folder each camera's image is read from, and LLFF's other resolutions (SCENE/images_N).
    for (const auto& cam : scene.cameras)
      if (fs::equivalent(out_dir, cam.image_path.parent_path(), ec))
        fail_file(out_dir, "holds the scene's images ({}): render into another folder", cam.image_name);
    const fs::path parent = fs::absolute(out_dir, ec).lexically_normal().parent_path();
    const std::string name = fs::absolute(out_dir, ec).lexically_normal().filename().string();
    if (name.rfind("images", 0) == 0 && fs::equivalent(parent, o.scene.source, ec))
      fail_file(out_dir, "is one of the scene's image folders: render into another folder");
  }
  std::map<std::string, int> taken;
  for (const int v : views) {
    const Camera& cam = scene.cameras[static_cast<std::size_t>(v)];
    const std::string stem = fs::path(cam.image_name).stem().string();
    if (const auto [it, fresh] = taken.emplace(stem, v); !fresh)
      fail("views {} ({}) and {} ({}) would both be written to {}: render them into separate folders (--split "
           "train, --split test)", it->second, scene.cameras[static_cast<std::size_t>(it->second)].image_name, v,
           cam.image_name, (out_dir / (stem + ".png")).string());
    for (const auto& name : output_names(stem, o))
      if (fs::exists(out_dir / name, ec))
        fail_file(out_dir / name, "exists: render writes a file per view and replaces none; choose a new or empty "
                  "folder, or remove it");
  }
}

int run_render(const RenderCommandOptions& o) {
  if (o.split != "test" && o.split != "train" && o.split != "all")
    fail("--split must be test, train or all (got '{}')", o.split);
  const render::DeviceChoice backend = resolve_device_flag(o.device, render::DeviceWork::Render);
  const std::filesystem::path out_dir = o.output;
  check_output_folder(out_dir);  // before any work: a path under a file fails now, not after rendering
  const Gaussians model = read_gaussians_ply(o.model);
  if (model.size() == 0) fail_file(o.model, "the model has no Gaussians (0 vertices): nothing to render");
  if (o.sh_degree > model.sh_degree)
    fail("option --sh-degree {} is above the SH degree {} of the model {} (use 0..{}, or -1 for the model's)",
         o.sh_degree, model.sh_degree, o.model, model.sh_degree);
  const auto [scene, split] = o.scene.load();
  std::vector<int> views;
  if (o.split == "test") views = split.test;
  else if (o.split == "train") views = split.train;
  else
    for (int i = 0; i < static_cast<int>(scene.cameras.size()); ++i) views.push_back(i);
  check_render_outputs(out_dir, scene, views, o);
  OutputSet outputs;  // a render that fails part-way takes back the views it wrote (none was there before)
  outputs.create_folder(out_dir);
  // One render at a time into a folder, the files checked again under its lock: two renders at once would
  // otherwise both find a name free and one replace the other's view.
  const FolderWriteLock lock(out_dir, ".d2gs-render.lock", "d2gs render");
  check_render_outputs(out_dir, scene, views, o);

  log_device_choice(backend);
  auto rasterizer = render::make_rasterizer(backend);
  render::RenderOptions ro;
  ro.background = scene.background;
  ro.sh_degree = o.sh_degree;
  spdlog::info("render: {} Gaussians (SH degree {}), {} {} view(s) of {} -> {}", model.size(), model.sh_degree,
               views.size(), o.split, o.scene.source, out_dir.string());
  for (const int v : views) {
    check_interrupted("while rendering (the views written so far are removed)");
    const Camera& cam = scene.cameras[static_cast<std::size_t>(v)];
    const auto& out = rasterizer->forward(model, nullptr, render::make_render_camera(cam), ro);
    const std::string stem = std::filesystem::path(cam.image_name).stem().string();
    Image rgb(cam.width, cam.height, 3);
    std::copy(out.rgb.begin(), out.rgb.end(), rgb.pixels.begin());  // write_image clamps to [0,1]
    write_image(outputs.file(out_dir / (stem + ".png")), rgb);
    if (o.alpha) {
      Image a(cam.width, cam.height, 1);
      std::copy(out.alpha.begin(), out.alpha.end(), a.pixels.begin());
      write_image(outputs.file(out_dir / (stem + "_alpha.png")), a);
    }
    if (o.depth) {
      Image d(cam.width, cam.height, 1);
      for (std::size_t p = 0; p < out.depth.size(); ++p)
        d.pixels[p] = out.alpha[p] > 1e-6f ? out.depth[p] / out.alpha[p] : 0.0f;
      write_npy_f32(outputs.file(out_dir / (stem + "_depth.npy")),
                    {static_cast<std::size_t>(cam.height), static_cast<std::size_t>(cam.width)}, d.pixels);
      write_png16(outputs.file(out_dir / (stem + "_depth.png")), d, 1000.0f);
    }
    spdlog::info("render: view {} {} ({}x{})", v, cam.image_name, cam.width, cam.height);
  }
  outputs.keep();
  return 0;
}

}  // namespace

Run add_render_command(CLI::App& app) {
  auto opts = std::make_shared<RenderCommandOptions>();
  CLI::App* sub = app.add_subcommand("render", "Render a trained model from a scene's cameras (one PNG per view)");
  add_option(*sub, "--model,-m", opts->model, "Model PLY (e.g. MODEL_DIR/point_cloud/iteration_10000/point_cloud.ply)")
      ->required()
      ->check(CLI::ExistingFile);
  add_scene_flags(*sub, opts->scene, SplitFlags::NViews);
  add_option(*sub, "-o,--output", opts->output, "Output folder")->required();
  add_option(*sub, "--split", opts->split, "Views to render: test, train or all")->capture_default_str();
  add_option(*sub, "--sh-degree", opts->sh_degree, "Active SH degree, 0..3 and at most the model's (-1 = the model's)")
      ->capture_default_str()
      ->check(in_range(-1, 3));
  sub->add_flag("--depth", opts->depth,
                "Also write <name>_depth.npy (float32, view-space z / alpha) and <name>_depth.png (16-bit, z*1000)");
  sub->add_flag("--alpha", opts->alpha, "Also write <name>_alpha.png (8-bit accumulated opacity)");
  add_device_flag(*sub, opts->device);
  return [opts]() -> int { return run_render(*opts); };
}

}  // namespace d2gs::cli
