// `d2gs imr` end to end: PLY files and run folders in, table and JSON out, same numbers as the library.
#include <fstream>
#include <random>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "d2gs/eval/imr.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/scene/scene.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

Gaussians random_model(std::size_t n, unsigned seed) {
  Gaussians g;
  g.resize(n, 1);
  std::mt19937 rng(seed);
  std::normal_distribution<float> n01;
  for (auto& v : g.means) v = n01(rng);
  for (auto& v : g.log_scales) v = -3.5f + 0.5f * n01(rng);
  for (auto& v : g.quats) v = n01(rng);
  for (auto& v : g.opacity_logits) v = n01(rng);
  return g;
}

TEST(ImrCli, PlyFilesAndRunFoldersAgreeWithTheLibrary) {
  const auto dir = test::scratch_dir();
  const std::vector<Gaussians> models = {random_model(900, 1), random_model(800, 2), random_model(700, 3)};
  write_gaussians_ply(dir / "a.ply", models[0]);
  std::filesystem::create_directories(dir / "run_b/point_cloud/iteration_1000");
  std::filesystem::create_directories(dir / "run_b/point_cloud/iteration_7000");
  write_gaussians_ply(dir / "run_b/point_cloud/iteration_1000/point_cloud.ply", models[2]);  // not the highest
  write_gaussians_ply(dir / "run_b/point_cloud/iteration_7000/point_cloud.ply", models[1]);
  write_gaussians_ply(dir / "c.ply", models[2]);
  const auto fern = test::shared_data() / "nerf_llff_data/fern";
  const auto r = test::run_cli("imr '" + (dir / "a.ply").string() + "' '" + (dir / "run_b").string() + "' '" +
                               (dir / "c.ply").string() + "' -s '" + fern.string() +
                               "' -r 8 --samples 300 --debiased --json '" + (dir / "imr.json").string() + "'");
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("IMR = "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("IMR (debiased) = "), std::string::npos) << r.output;
  EXPECT_NE(r.output.find("iteration_7000"), std::string::npos) << r.output;
  std::ifstream in(dir / "imr.json");
  const nlohmann::json j = nlohmann::json::parse(in);
  ASSERT_EQ(j["pairs"].size(), 3u);
  ASSERT_EQ(j["self"].size(), 3u);

  SceneLoadOptions load;
  load.resolution = 8;
  const Camera cam = load_scene(fern, load).cameras[0];
  ImrOptions o;
  o.mixture.samples = 300;
  o.debiased = true;
  std::vector<GaussianMixture> mixtures;
  for (const auto& m : models) mixtures.push_back(mixture_from_model(m, cam, o.mixture));
  const ImrResult expected = compute_imr(mixtures, o);
  EXPECT_DOUBLE_EQ(j["imr"].get<double>(), expected.imr);
  EXPECT_DOUBLE_EQ(j["imr_debiased"].get<double>(), *expected.imr_debiased);
  for (std::size_t k = 0; k < 3; ++k) {
    EXPECT_DOUBLE_EQ(j["pairs"][k]["transport_cost"].get<double>(), expected.pairs[k].transport.transport_cost);
    EXPECT_TRUE(j["pairs"][k]["converged"].get<bool>());
  }
  EXPECT_EQ(j["models"][1]["components"].get<std::size_t>(), mixtures[1].size());

  // ε-scaling is the default; without it the solver reaches the same plan from ε itself.
  EXPECT_TRUE(j["options"]["epsilon_scaling"].get<bool>());
  const auto plain = test::run_cli("imr '" + (dir / "a.ply").string() + "' '" + (dir / "c.ply").string() + "' -s '" +
                                   fern.string() + "' -r 8 --samples 300 --no-epsilon-scaling --json '" +
                                   (dir / "plain.json").string() + "'");
  ASSERT_EQ(plain.exit_code, 0) << plain.output;
  std::ifstream in_plain(dir / "plain.json");
  const nlohmann::json p = nlohmann::json::parse(in_plain);
  EXPECT_FALSE(p["options"]["epsilon_scaling"].get<bool>());
  const double scaled_cost = expected.pairs[1].transport.transport_cost;  // pair (a, c)
  EXPECT_NEAR(p["pairs"][0]["transport_cost"].get<double>(), scaled_cost, 1e-4 * scaled_cost);
}

TEST(ImrCli, WarnsWithoutSceneAndRejectsBadInput) {
  const auto dir = test::scratch_dir();
  write_gaussians_ply(dir / "a.ply", random_model(200, 4));
  write_gaussians_ply(dir / "b.ply", random_model(200, 5));
  const std::string a = "'" + (dir / "a.ply").string() + "'", b = "'" + (dir / "b.ply").string() + "'";
  const auto ok = test::run_cli("imr " + a + " " + b + " --cost on-the-fly");
  EXPECT_EQ(ok.exit_code, 0) << ok.output;
  EXPECT_NE(ok.output.find("identity camera"), std::string::npos) << ok.output;
  EXPECT_EQ(test::run_cli("imr " + a).exit_code, 1);
  EXPECT_EQ(test::run_cli("imr " + a + " " + b + " --cost sparse").exit_code, 1);
  const auto missing = test::run_cli("imr " + a + " '" + (dir / "nothing").string() + "'");
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_NE(missing.output.find("no such model file or run folder"), std::string::npos) << missing.output;
  const auto empty_run = test::run_cli("imr " + a + " '" + dir.string() + "'");
  EXPECT_EQ(empty_run.exit_code, 1);
  EXPECT_NE(empty_run.output.find("point_cloud/iteration_N"), std::string::npos) << empty_run.output;
}

}  // namespace
}  // namespace d2gs
