#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "d2gs/core/error.hpp"
#include "d2gs/train/presets.hpp"

namespace d2gs {
namespace {

TEST(Presets, PaperAndRelease) {
  TrainConfig c;
  // The defaults are the release preset's values (chosen by measurement, docs/training.md).
  EXPECT_EQ(c.dd_drop.depth_mode, DepthMode::ReleaseDot);
  EXPECT_TRUE(c.dd_drop.release_density_cache);
  EXPECT_DOUBLE_EQ(c.dd_drop.weight_depth, 0.3);
  EXPECT_DOUBLE_EQ(c.dd_drop.weight_density, 0.7);
  EXPECT_DOUBLE_EQ(c.dd_drop.rate_min, 0.05);
  EXPECT_DOUBLE_EQ(c.dd_drop.rate_max, 0.3);
  EXPECT_EQ(c.dafe.loss_form, DafeLossForm::Release);
  apply_d2gs_preset(c, "paper");
  apply_d2gs_preset(c, "release");
  EXPECT_EQ(c.dd_drop.depth_mode, DepthMode::ReleaseDot);
  EXPECT_TRUE(c.dd_drop.release_density_cache);
  EXPECT_DOUBLE_EQ(c.dd_drop.weight_depth, 0.3);
  EXPECT_DOUBLE_EQ(c.dd_drop.weight_density, 0.7);
  EXPECT_EQ(c.dafe.loss_form, DafeLossForm::Release);
  apply_d2gs_preset(c, "paper");
  EXPECT_EQ(c.dd_drop.depth_mode, DepthMode::Euclidean);
  EXPECT_FALSE(c.dd_drop.release_density_cache);
  EXPECT_DOUBLE_EQ(c.dd_drop.weight_depth, 0.5);
  EXPECT_DOUBLE_EQ(c.dafe.tau, 5.0);
  EXPECT_EQ(c.dafe.loss_form, DafeLossForm::Paper);
  EXPECT_THROW(apply_d2gs_preset(c, "best"), Error);
  // release undoes everything paper sets, the far mask's τ and λ_DAFE included: the two
  // presets leave the same config whatever came before.
  TrainConfig changed;
  changed.dafe.tau = 12.0;
  changed.dafe.lambda = 0.25f;
  changed.dafe.mask_rule = DafeMaskRule::Threshold;
  apply_d2gs_preset(changed, "paper");
  apply_d2gs_preset(changed, "release");
  TrainConfig released;
  apply_d2gs_preset(released, "release");
  nlohmann::json a, b;
  to_json(a, changed);
  to_json(b, released);
  EXPECT_EQ(a, b) << a.dump(1) << "\n" << b.dump(1);
}

// "plus" is the release with exactly three things changed: compensation per Gaussian, opacity decay
// among the regularisers (once, however often the preset is applied), and no opacity reset.
TEST(Presets, PlusIsTheReleaseWithCompensationAndDecay) {
  TrainConfig plus;
  plus.dd_drop.weight_depth = 0.9;  // a value the release restores
  plus.dd_drop.depth_mode = DepthMode::Euclidean;
  apply_d2gs_preset(plus, "plus");
  apply_d2gs_preset(plus, "plus");
  TrainConfig expected;
  apply_d2gs_preset(expected, "release");
  EXPECT_FALSE(expected.dd_drop.compensate);
  EXPECT_FALSE(expected.opacity_reset_at.empty());
  expected.dd_drop.compensate = true;
  expected.regularisers = {"opacity-decay"};
  expected.opacity_reset_at.clear();
  nlohmann::json a, b;
  to_json(a, plus);
  to_json(b, expected);
  EXPECT_EQ(a, b) << a.dump(1) << "\n" << b.dump(1);
  TrainConfig noisy;
  noisy.regularisers = {"opacity-noise"};
  apply_d2gs_preset(noisy, "plus");  // a regulariser chosen before stays, in front
  EXPECT_EQ(noisy.regularisers, (std::vector<std::string>{"opacity-noise", "opacity-decay"}));
}

// Every name --preset lists applies; the command line refuses a D²GS preset for another method
// (plus would switch on opacity decay and drop the reset of DropGaussian's training).
TEST(Presets, NamesApplyAndOnlyToD2gs) {
  EXPECT_EQ(d2gs_preset_names(), (std::vector<std::string>{"paper", "release", "plus"}));
  for (const std::string& name : d2gs_preset_names()) {
    TrainConfig c;
    c.method = "d2gs";
    EXPECT_NO_THROW(apply_given_options(c, {{"preset", name}})) << name;
    EXPECT_EQ(c.preset, name);
    for (const char* other : {"3dgs", "dropgaussian"}) {
      TrainConfig o;
      o.method = other;
      const TrainConfig before = o;
      try {
        apply_given_options(o, {{"preset", name}});
        ADD_FAILURE() << "--preset " << name << " accepted for " << other;
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("is a D2GS preset, but the method is " + std::string(other)),
                  std::string::npos)
            << e.what();
      }
      nlohmann::json a, b;
      to_json(a, o);
      to_json(b, before);
      EXPECT_EQ(a, b) << "a refused preset changed the config";
    }
    // The method given on the same command line counts, whatever the config held before.
    TrainConfig switched;
    switched.method = "dropgaussian";
    EXPECT_NO_THROW(apply_given_options(switched, {{"method", "d2gs"}, {"preset", name}}));
    EXPECT_THROW(apply_given_options(c, {{"method", "3dgs"}, {"preset", name}}), Error);
  }
  TrainConfig c;
  c.method = "d2gs";
  try {
    apply_given_options(c, {{"preset", "best"}});
    ADD_FAILURE() << "an unknown preset was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("expected one of: paper, release, plus"), std::string::npos) << e.what();
  }
}

TEST(Presets, SceneValuesOfTheRelease) {
  TrainConfig c;
  apply_scene_preset(c, "fern");
  EXPECT_DOUBLE_EQ(c.dd_drop.weight_depth, 0.7);
  EXPECT_DOUBLE_EQ(c.dd_drop.rate_min, 0.1);
  EXPECT_DOUBLE_EQ(c.dafe.tau, 10.0);
  EXPECT_FLOAT_EQ(c.dafe.lambda, 1.0f);
  apply_scene_preset(c, "llff/leaves");
  EXPECT_DOUBLE_EQ(c.dd_drop.rate_max, 0.5);
  EXPECT_FLOAT_EQ(c.dafe.lambda, 0.25f);
  apply_scene_preset(c, "mipnerf360/garden");
  EXPECT_DOUBLE_EQ(c.dd_drop.rate_max, 0.7);
  EXPECT_DOUBLE_EQ(c.dafe.tau, 15.0);
  EXPECT_THROW(apply_scene_preset(c, "room"), Error);  // LLFF and Mip-NeRF 360 both have a room
  EXPECT_THROW(apply_scene_preset(c, "lego"), Error);
  EXPECT_EQ(d2gs_scene_presets().size(), 15u);
  for (const auto& p : d2gs_scene_presets()) EXPECT_NEAR(p.weight_depth + p.weight_density, 1.0, 1e-12) << p.scene;
}

}  // namespace
}  // namespace d2gs
