// d2gs demo: the first command a user runs. Generates the built-in synthetic scene (analytic ray tracer,
// no downloaded data) in LLFF layout and says what to run next.
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <string>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "cli/commands.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/scene/synthetic_scene.hpp"

namespace d2gs::cli {
namespace {

struct DemoOptions {
  std::string output = "demo";
  std::uint64_t seed = 0;
  int views = 20;
};

std::string quoted(const std::string& s) {
  return s.find_first_of(" \t'\"\\$`") == std::string::npos ? s : "'" + s + "'";
}

int run_demo(const DemoOptions& opt) {
  SyntheticSceneOptions scene;
  scene.seed = opt.seed;
  scene.views = opt.views;
  validate(scene);
  const std::filesystem::path dir = opt.output;
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
              "true depth maps (depth/), a point cloud (points3D.ply) and scene.json.\n"
              "Next: d2gs info -s %s   (cameras and the sparse-view split)\n",
              dir.string().c_str(), seconds, scene.views, scene.width, scene.height, d.c_str());
  return 0;
}

}  // namespace

Run add_demo_command(CLI::App& app) {
  auto opt = std::make_shared<DemoOptions>();
  auto* sub = app.add_subcommand(
      "demo", "Generate the built-in synthetic scene (ray-traced, LLFF layout, with true depth) to try d2gs on");
  sub->add_option("-o,--output", opt->output, "Folder to write (created; refused if it holds other data)")
      ->capture_default_str();
  sub->add_option("--seed", opt->seed, "Seed of the scene (layout jitter, colours, textures)")->capture_default_str();
  sub->add_option("--views", opt->views, "Number of cameras")->capture_default_str()->check(CLI::Range(2, 1000));
  return [opt]() -> int { return run_demo(*opt); };
}

}  // namespace d2gs::cli
