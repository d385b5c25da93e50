// d2gs render on the real fern scene (shared data) with a model made from its SfM points.
#include <unistd.h>

#include <cmath>

#include <gtest/gtest.h>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/image.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/scene/scene.hpp"
#include "test_paths.hpp"

namespace d2gs::test {
namespace {

TEST(RenderCli, RendersTestViewsWithDepthAndAlpha) {
  const auto fern = shared_data() / "nerf_llff_data/fern";
  ASSERT_TRUE(std::filesystem::exists(fern)) << fern;
  const auto dir = scratch_dir();
  SceneLoadOptions load;
  load.resolution = 8;
  const Scene scene = load_scene(fern, load);
  ASSERT_FALSE(scene.sfm_points.empty());
  Gaussians model;
  model.resize(scene.sfm_points.size(), 1);
  for (std::size_t i = 0; i < model.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      model.means[i * 3 + k] = scene.sfm_points.positions[i][k];
      model.log_scales[i * 3 + k] = std::log(0.02f);
      model.sh_dc[i * 3 + k] = (scene.sfm_points.colors[i][k] / 255.0f - 0.5f) / 0.28209479f;
    }
    model.opacity_logits[i] = 2.0f;
  }
  write_gaussians_ply(dir / "model.ply", model);
  const auto r = run_cli("render --model '" + (dir / "model.ply").string() + "' -s '" + fern.string() +
                         "' -r 8 -o '" + (dir / "out").string() + "' --depth --alpha");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // fern has 20 images: test views 0, 8, 16.
  for (const char* name : {"image000", "image008", "image016"}) {
    const Image rgb = read_image(dir / "out" / (std::string(name) + ".png"));
    EXPECT_EQ(rgb.width, 504);
    EXPECT_EQ(rgb.height, 378);
    const Image alpha = read_image(dir / "out" / (std::string(name) + "_alpha.png"));
    double mean_alpha = 0;
    for (float v : alpha.pixels) mean_alpha += v;
    mean_alpha /= double(alpha.pixels.size());
    EXPECT_GT(mean_alpha, 0.03) << name;  // sparse SfM points: ~9% coverage
    const NpyArray depth = read_npy(dir / "out" / (std::string(name) + "_depth.npy"));
    ASSERT_EQ(depth.shape, (std::vector<std::size_t>{378, 504}));
    EXPECT_TRUE(std::filesystem::exists(dir / "out" / (std::string(name) + "_depth.png")));
  }
  // A render that fails part-way (here each file is limited to 400 kB: the first view's PNGs fit, its
  // 762 kB depth map does not, as on a full disk) takes back what it wrote: no folder is left for the
  // next render to refuse.
  const std::string again = "render --model '" + (dir / "model.ply").string() + "' -s '" + fern.string() +
                            "' -r 8 -o '" + (dir / "partial").string() + "' --depth --alpha";
  ASSERT_LT(std::filesystem::file_size(dir / "out/image000.png"), 400000u);
  const auto partial = run_cli_with_file_size_limit(again, 400000);
  EXPECT_EQ(partial.exit_code, 1) << partial.output;
  EXPECT_NE(partial.output.find((dir / "partial/image000_depth.npy").string() + ": write failed"), std::string::npos)
      << partial.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "partial"));
  // While another render writes into the folder (its lock held here), a second one writes nothing there.
  {
    std::filesystem::create_directories(dir / "partial");
    const auto held = FileLock::try_acquire(dir / "partial/.d2gs-render.lock");
    ASSERT_TRUE(held);
    const auto busy = run_cli(again);
    EXPECT_EQ(busy.exit_code, 1) << busy.output;
    EXPECT_NE(busy.output.find((dir / "partial").string() + ": another d2gs render (process " +
                               std::to_string(::getpid()) + ") is writing into this folder"),
              std::string::npos)
        << busy.output;
    EXPECT_FALSE(std::filesystem::exists(dir / "partial/image000.png"));
    std::filesystem::remove(dir / "partial/.d2gs-render.lock");
  }
  EXPECT_EQ(run_cli(again).exit_code, 0);
  EXPECT_FALSE(std::filesystem::exists(dir / "partial/.d2gs-render.lock"));  // nothing left behind
  const auto bad = run_cli("render --model '" + (dir / "model.ply").string() + "' -s '" + fern.string() +
                           "' -o '" + (dir / "x").string() + "' --split nope");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("--split"), std::string::npos) << bad.output;
}

// Bad options and models fail before anything is rendered or written.
TEST(RenderCli, RefusesShDegreeAboveTheModelsAnEmptyModelAndAnOutputUnderAFile) {
  const auto fern = shared_data() / "nerf_llff_data/fern";
  const auto dir = scratch_dir();
  Gaussians model;
  model.resize(50, 1);  // SH degree 1
  for (std::size_t i = 0; i < model.size(); ++i) model.means[i * 3 + 2] = 5.0f;
  write_gaussians_ply(dir / "degree1.ply", model);
  const auto render = [&](const std::string& ply, const std::string& out, const std::string& extra) {
    return run_cli("render --model '" + ply + "' -s '" + fern.string() + "' -r 8 -o '" + out + "' " + extra);
  };
  // Degree 10 used to render degree 3 silently.
  const auto ten = render((dir / "degree1.ply").string(), (dir / "out").string(), "--sh-degree 10");
  EXPECT_NE(ten.exit_code, 0) << ten.output;
  EXPECT_NE(ten.output.find("--sh-degree"), std::string::npos) << ten.output;
  const auto two = render((dir / "degree1.ply").string(), (dir / "out").string(), "--sh-degree 2");
  EXPECT_EQ(two.exit_code, 1) << two.output;
  EXPECT_NE(two.output.find("--sh-degree 2 is above the SH degree 1 of the model"), std::string::npos) << two.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "out"));
  const auto one = render((dir / "degree1.ply").string(), (dir / "out").string(), "--sh-degree 1");
  EXPECT_EQ(one.exit_code, 0) << one.output;
  // A model without Gaussians used to render black images with exit 0.
  write_gaussians_ply(dir / "empty.ply", Gaussians{});
  const auto empty = render((dir / "empty.ply").string(), (dir / "empty_out").string(), "");
  EXPECT_EQ(empty.exit_code, 1) << empty.output;
  EXPECT_NE(empty.output.find((dir / "empty.ply").string() + ": the model has no Gaussians"), std::string::npos)
      << empty.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "empty_out"));
  // An output folder under a file: said before rendering, not "internal: filesystem error" after.
  const auto under = render((dir / "degree1.ply").string(), (dir / "degree1.ply/out").string(), "");
  EXPECT_EQ(under.exit_code, 1) << under.output;
  EXPECT_NE(under.output.find("is a file, not a folder"), std::string::npos) << under.output;
  EXPECT_EQ(under.output.find("internal"), std::string::npos) << under.output;
  // A folder that cannot be created although its parent looks writable (root in /proc): one line, exit 1.
  const auto proc = render((dir / "degree1.ply").string(), "/proc/d2gs_render_test", "");
  EXPECT_EQ(proc.exit_code, 1) << proc.output;
  EXPECT_NE(proc.output.find("/proc/d2gs_render_test"), std::string::npos) << proc.output;
  EXPECT_EQ(proc.output.find("internal"), std::string::npos) << proc.output;
}

// render replaces no file: not its own earlier renders, not the scene's images, and no two views of one
// command (Blender's train/r_0 and test/r_0 have one stem).
TEST(RenderCli, ReplacesNoFileAndWritesNoTwoViewsToOne) {
  const auto fern = shared_data() / "nerf_llff_data/fern";
  const auto lego = shared_data() / "nerf_synthetic/lego";
  const auto dir = scratch_dir();
  Gaussians model;
  model.resize(50, 0);
  for (std::size_t i = 0; i < model.size(); ++i) model.means[i * 3 + 2] = 5.0f;
  write_gaussians_ply(dir / "m.ply", model);
  const auto render = [&](const std::filesystem::path& scene, const std::filesystem::path& out, const std::string& extra) {
    return run_cli("render --model '" + (dir / "m.ply").string() + "' -s '" + scene.string() + "' -r 8 -o '" +
                   out.string() + "' " + extra);
  };
  ASSERT_EQ(render(fern, dir / "out", "").exit_code, 0);
  const std::string first = read_file(dir / "out/image008.png");
  const auto again = render(fern, dir / "out", "");
  EXPECT_EQ(again.exit_code, 1) << again.output;
  EXPECT_NE(again.output.find((dir / "out/image000.png").string() + ": exists"), std::string::npos) << again.output;
  // --alpha's files are new, but the RGB ones are not: still refused, and nothing was written.
  EXPECT_EQ(render(fern, dir / "out", "--alpha").exit_code, 1);
  EXPECT_FALSE(std::filesystem::exists(dir / "out/image000_alpha.png"));
  EXPECT_EQ(read_file(dir / "out/image008.png"), first);
  const auto own = render(fern, fern / "images_8", "");
  EXPECT_EQ(own.exit_code, 1) << own.output;
  EXPECT_NE(own.output.find("is one of the scene's image folders"), std::string::npos) << own.output;
  const auto both = render(lego, dir / "lego", "--split all");
  EXPECT_EQ(both.exit_code, 1) << both.output;
  EXPECT_NE(both.output.find("would both be written to " + (dir / "lego/r_0.png").string()), std::string::npos)
      << both.output;
  EXPECT_FALSE(std::filesystem::exists(dir / "lego"));
}

}  // namespace
}  // namespace d2gs::test
