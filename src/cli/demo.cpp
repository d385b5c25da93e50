// d2gs demo: the first command a user runs. Generates the built-in synthetic scene (analytic ray tracer,
// no downloaded data) in LLFF layout, trains D²GS on 3 of its views with a short schedule, evaluates the
// held-out views and writes the HTML report; prints where the report is.
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "cli/commands.hpp"
#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/image.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/demo/synthetic_scene.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/report/run_report.hpp"
#include "d2gs/scene/scene.hpp"
#include "d2gs/scene/split.hpp"
#include "d2gs/train/trainer.hpp"

namespace d2gs::cli {
namespace {

struct DemoOptions {
  std::string output = "demo";
  std::uint64_t seed = 0;
  int views = 20;
  bool scene_only = false;
  int iterations = 1000;
  int resolution = 2;
  int train_views = 3;
  std::string init = "dense";
  std::string dense_method = "sgbm";
};

// Initial points from the training views only: every `stride`-th pixel of each training view's true
// depth map (depth/NAME.npy, full resolution) lifted to the world, coloured by the image (--init
// training-depth: what the estimated geometry of the default --init dense would be if it were perfect);
// the test views contribute nothing, unlike points3D.ply.
PointCloud training_view_points(const std::filesystem::path& dir, const std::vector<int>& train, int per_view) {
  const Scene full = load_scene(dir);  // full resolution, the depth maps' size
  PointCloud cloud;
  for (int index : train) {
    const Camera& cam = full.cameras.at(static_cast<std::size_t>(index));
    const auto npy = dir / "depth" / (std::filesystem::path(cam.image_name).stem().string() + ".npy");
    const NpyArray depth = read_npy(npy);
    if (depth.shape.size() != 2 || depth.shape[0] != static_cast<std::size_t>(cam.height) ||
        depth.shape[1] != static_cast<std::size_t>(cam.width))
      fail_file(npy, "expected a {}x{} depth map", cam.height, cam.width);
    const Image image = load_image(full, index);
    const int stride = std::max(1, static_cast<int>(std::lround(std::sqrt(double(cam.width) * cam.height / per_view))));
    const glm::dmat3 to_world = cam.R_cam_to_world();
    const glm::dvec3 centre = cam.center_world();
    for (int y = stride / 2; y < cam.height; y += stride)
      for (int x = stride / 2; x < cam.width; x += stride) {
        const double z = depth.values[static_cast<std::size_t>(y) * static_cast<std::size_t>(cam.width) + x];
        if (!(z > 0.0) || !std::isfinite(z)) continue;
        const glm::dvec3 c{(x + 0.5 - cam.cx) / cam.fx * z, (y + 0.5 - cam.cy) / cam.fy * z, z};
        cloud.positions.push_back(glm::vec3(centre + to_world * c));
        const auto channel = [&](int k) {
          return static_cast<std::uint8_t>(std::lround(std::clamp(image.at(x, y, k), 0.0f, 1.0f) * 255.0f));
        };
        cloud.colors.emplace_back(channel(0), channel(1), channel(2));
      }
  }
  return cloud;
}

// The file by which a demo marks OUTPUT/run as its own, to be replaced by the next demo there.
constexpr const char* kDemoRunMarker = ".d2gs-demo-run";

std::string quoted(const std::string& s) {
  return s.find_first_of(" \t'\"\\$`") == std::string::npos ? s : "'" + s + "'";
}

int run_demo(const DemoOptions& opt) {
  SyntheticSceneOptions scene;
  scene.seed = opt.seed;
  scene.views = opt.views;
  validate(scene);
  const std::filesystem::path dir = opt.output;
  check_output_folder(dir);
  if (!opt.scene_only) {
    // The training split of the scene to be written, checked before any view is rendered.
    Scene planned;
    planned.root = dir;
    planned.format = SceneFormat::Llff;
    planned.cameras = synthetic_scene_cameras(scene);
    SplitOptions so;
    so.n_views = opt.train_views;
    try {
      make_split(planned, so);
    } catch (const Error& e) {
      fail("demo: --views {} with --n-views {}: {}", opt.views, opt.train_views, e.what());
    }
  }
  // One demo at a time into a folder, from the checks below to the end of its run: two would otherwise mix
  // their scene files, and one could remove the run the other trains. The folder, when made here, goes
  // again if the demo fails before writing into it.
  OutputSet folder;
  folder.create_folder(dir);
  const FolderWriteLock lock(dir, kSyntheticSceneLock, "d2gs demo");
  // OUTPUT/run is replaced only when an earlier demo marked it as its own, checked before any work.
  const std::filesystem::path run_dir = dir / "run";
  std::error_code ec;
  bool replace_run = false;
  if (!opt.scene_only && std::filesystem::exists(run_dir, ec)) {
    if (!std::filesystem::is_directory(run_dir, ec)) fail_file(run_dir, "exists and is not a folder (the demo trains its run there)");
    replace_run = std::filesystem::is_regular_file(run_dir / kDemoRunMarker, ec);
    if (!replace_run && !std::filesystem::is_empty(run_dir, ec))
      fail_file(run_dir, "holds files the demo did not write (a run of yours, or one of a demo before {} marked its own): "
                "move it away or choose another -o", kDemoRunMarker);
  }
  // Progress on one line when stderr is a terminal and progress lines are wanted.
  const bool show = spdlog::default_logger()->should_log(spdlog::level::info);
  const bool tty = ::isatty(STDERR_FILENO) != 0;
  if (show)
    std::fprintf(stderr, "demo: generating the synthetic scene (%d views, %dx%d, seed %llu) in %s\n", scene.views,
                 scene.width, scene.height, static_cast<unsigned long long>(scene.seed), dir.string().c_str());
  const auto start = std::chrono::steady_clock::now();
  write_synthetic_scene(dir, scene, [&](int done, int total) {
    if (show && tty) {
      std::fprintf(stderr, "\rdemo: rendered view %d/%d", done, total);
      if (done == total) std::fputc('\n', stderr);
      std::fflush(stderr);
    }
  });
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  const std::string d = quoted(dir.string());
  std::printf("Synthetic scene written to %s in %.1f s: %d views of %dx%d (images/, poses_bounds.npy),\n"
              "true depth maps (depth/), a point cloud (points3D.ply) and scene.json.\n",
              dir.string().c_str(), seconds, scene.views, scene.width, scene.height);
  if (opt.scene_only) {
    std::printf("Next: d2gs info -s %s   (cameras and the sparse-view split)\n", d.c_str());
    folder.keep();
    return 0;
  }
  std::fflush(stdout);

  // A short D²GS schedule on the sparse split: densification from iteration 100 (not 500) so that it
  // happens within the budget; everything else is the method's default.
  if (replace_run) std::filesystem::remove_all(run_dir);  // an earlier demo's (checked above)
  TrainConfig c;
  c.source = std::filesystem::absolute(dir).lexically_normal().string();  // recorded absolute, as d2gs train does
  c.model_dir = run_dir.string();
  c.resolution = opt.resolution;
  c.n_views = opt.train_views;
  c.method = "d2gs";
  c.iterations = opt.iterations;
  c.seed = opt.seed;
  if (opt.init == "training-depth") {
    // Written beside the scene, so that the run's recorded init names a file that exists.
    SplitOptions so;
    so.n_views = opt.train_views;
    const Split split = load_scene_and_split(dir, {}, so).split;
    const auto ply = dir / "init_training_views.ply";
    write_point_cloud_ply(ply, training_view_points(dir, split.train, 10000 / std::max<int>(1, split.train.size())));
    c.init = ply.string();
  } else {
    // dense / sparse: the trainer runs d2gs init on the training images (cached in RUN/init); random.
    c.init = opt.init == "points" ? (dir / "points3D.ply").string() : opt.init;
  }
  c.init_dense_method = opt.dense_method;
  c.densify_from = std::min(100, opt.iterations);
  c.densify_until = opt.iterations;
  for (int k = 1; k <= 6; ++k) c.test_iterations.push_back(std::max(1, opt.iterations * k / 6));
  c.test_iterations.erase(std::unique(c.test_iterations.begin(), c.test_iterations.end()), c.test_iterations.end());
  c.quiet = !show;
  c.validate();
  if (show)
    std::fprintf(stderr, "demo: training D²GS on %d views at 1/%d resolution for %d iterations (init: %s) in %s\n",
                 c.n_views, c.resolution, c.iterations, c.init.c_str(), run_dir.string().c_str());
  Trainer trainer(c);
  write_file_atomic(run_dir / kDemoRunMarker, "written by d2gs demo: the next demo in this folder replaces this run\n");
  const EvalSummary before = trainer.evaluate_test_views();
  trainer.run();
  const EvalSummary after = trainer.evaluate_test_views();
  const std::filesystem::path page = report::write_run_report(run_dir);
  const double total = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("Trained D²GS on %d of the %d views (%d iterations, %zu Gaussians) in %s.\n"
              "Held-out views: PSNR %.2f dB -> %.2f dB, SSIM %.3f -> %.3f (initial model -> trained).\n"
              "Total %.0f s. Next: d2gs info -s %s; d2gs train --help (longer runs, other methods).\n"
              "Report: %s\n",
              c.n_views, scene.views, c.iterations, trainer.model().size(), run_dir.string().c_str(), before.psnr,
              after.psnr, before.ssim, after.ssim, total, d.c_str(), page.string().c_str());
  folder.keep();
  return 0;
}

}  // namespace

Run add_demo_command(CLI::App& app) {
  auto opt = std::make_shared<DemoOptions>();
  auto* sub = app.add_subcommand(
      "demo",
      "Generate the built-in synthetic scene (ray-traced, LLFF layout, with true depth), train D²GS on 3 of its "
      "views with the default settings of d2gs train --method d2gs (the release preset), evaluate the held-out views and write the HTML report (RUN = OUTPUT/run)");
  add_option(*sub, "-o,--output", opt->output, "Folder to write (created; refused if it holds other data)")
      ->capture_default_str();
  add_option(*sub, "--seed", opt->seed, "Seed of the scene (layout jitter, colours, textures)")->capture_default_str();
  add_option(*sub, "--views", opt->views, "Number of cameras")->capture_default_str()->check(in_range(2, 1000));
  sub->add_flag("--scene-only", opt->scene_only, "Only generate the scene (no training, no report)");
  add_option(*sub, "--iterations", opt->iterations, "Training iterations of the demo run")
      ->capture_default_str()
      ->check(in_range(1, 100000));
  add_option(*sub, "-r,--resolution", opt->resolution, "Train and evaluate at 1/R of the scene's resolution")
      ->capture_default_str()
      ->check(CLI::IsMember({1, 2, 4, 8}));
  add_option(*sub, "--n-views", opt->train_views, "Training views of the sparse-view split")
      ->capture_default_str()
      ->check(in_range(1, 1000));
  add_option(*sub, "--init", opt->init,
             "Initial points: 'dense' (stereo + fusion of the training images, as d2gs init and d2gs "
             "train do), 'sparse' (SIFT triangulation of the training images), 'training-depth' (the true "
             "depth of the training views only, lifted to 3D; written to OUTPUT/init_training_views.ply), "
             "'random', or 'points' (the scene's points3D.ply, sampled from every view: an oracle)")
      ->capture_default_str()
      ->check(CLI::IsMember({"dense", "sparse", "training-depth", "random", "points"}));
  add_option(*sub, "--dense-method", opt->dense_method,
             "Stereo of --init dense: 'sgbm' or 'patchmatch' (as d2gs train --init-dense-method)")
      ->capture_default_str()
      ->check(CLI::IsMember({"sgbm", "patchmatch"}));
  return [opt]() -> int { return run_demo(*opt); };
}

}  // namespace d2gs::cli
