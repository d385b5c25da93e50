// d2gs render on the real fern scene (shared data) with a model made from its SfM points.
#include <cmath>

#include <gtest/gtest.h>

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
  const auto bad = run_cli("render --model '" + (dir / "model.ply").string() + "' -s '" + fern.string() +
                           "' -o '" + (dir / "x").string() + "' --split nope");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_NE(bad.output.find("--split"), std::string::npos) << bad.output;
}

}  // namespace
}  // namespace d2gs::test
