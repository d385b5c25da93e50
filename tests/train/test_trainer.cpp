// End-to-end training on real data (fern, 3 views, 504×378): short runs that check learning,
// determinism, resume and the output layout.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <memory>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/core/image.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/render/rasterizer.hpp"
#include "d2gs/train/losses.hpp"
#include "d2gs/train/initialize.hpp"
#include "d2gs/train/trainer.hpp"
#include "test_errors.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

TrainConfig fern_config(const fs::path& out, const std::string& method, int iterations) {
  TrainConfig c;
  c.source = (test::shared_data() / "nerf_llff_data/fern").string();
  c.model_dir = out.string();
  c.resolution = 8;
  c.n_views = 3;
  c.method = method;
  c.iterations = iterations;
  c.quiet = true;
  c.seed = 1;
  // These tests are about training, not its initial points: SGBM's geometry of the training views takes
  // seconds where the default PatchMatch at 1008×756 takes a minute or more (tested on its own below
  // and in tests/geometry).
  c.init_dense_method = "sgbm";
  return c;
}

// Every parameter of the two models, bit for bit.
void expect_same_model(const Gaussians& got, const Gaussians& want) {
  EXPECT_EQ(got.size(), want.size());
  EXPECT_EQ(got.means, want.means);
  EXPECT_EQ(got.log_scales, want.log_scales);
  EXPECT_EQ(got.quats, want.quats);
  EXPECT_EQ(got.opacity_logits, want.opacity_logits);
  EXPECT_EQ(got.sh_dc, want.sh_dc);
  EXPECT_EQ(got.sh_rest, want.sh_rest);
}

// The runs of a regulariser test: `cfg` trained in DIR/a with a checkpoint at iteration `resume_at`; the
// same run resumed from that checkpoint in DIR/b, which must end in DIR/a's model bit for bit (a
// regulariser that loses state on resume fails here); and the same run without regularisers in DIR/c.
struct RegularisedAndPlain {
  std::unique_ptr<Trainer> regularised;  // DIR/a
  std::unique_ptr<Trainer> plain;        // DIR/c
};
RegularisedAndPlain train_resume_and_train_plain(TrainConfig cfg, const fs::path& dir, int resume_at) {
  RegularisedAndPlain runs;
  cfg.model_dir = (dir / "a").string();
  cfg.checkpoint_iterations = {resume_at};
  runs.regularised = std::make_unique<Trainer>(cfg);
  runs.regularised->run();
  auto cfg_b = cfg;
  cfg_b.model_dir = (dir / "b").string();
  cfg_b.checkpoint_iterations = {};
  Trainer b(cfg_b, dir / "a" / fmt::format("chkpnt{}.bin", resume_at));
  EXPECT_EQ(b.iteration(), resume_at);
  b.run();
  expect_same_model(b.model(), runs.regularised->model());

  auto cfg_c = cfg_b;
  cfg_c.model_dir = (dir / "c").string();
  cfg_c.regularisers = {};
  runs.plain = std::make_unique<Trainer>(cfg_c);
  runs.plain->run();
  return runs;
}

// The last line of a train_log.jsonl that reports an iteration ("" when there is none).
std::string last_iteration_line(const fs::path& log_file) {
  std::ifstream log(log_file);
  std::string line, last;
  while (std::getline(log, line))
    if (nlohmann::json::parse(line).contains("iteration")) last = line;
  return last;
}

TEST(Trainer, TestPsnrRisesWellAboveTheInitialRender) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "run", "3dgs", 300);
  cfg.densify_from = 100;  // densify within the short schedule
  cfg.init = "sfm-all-views";  // the labelled oracle (the default is the training views' own geometry)
  Trainer trainer(cfg);
  const double before = trainer.evaluate_test_views().psnr;
  trainer.run();
  const auto results = nlohmann::json::parse(read_file(dir / "run/results.json"));
  const double after = results["mean"]["PSNR"];
  RecordProperty("psnr_before", std::to_string(before));
  RecordProperty("psnr_after", std::to_string(after));
  std::printf("fern 3 views, 300 iterations: test PSNR %.2f -> %.2f dB\n", before, after);
  EXPECT_GT(after, before + 3.0);
  EXPECT_TRUE(results["init_is_oracle"].get<bool>());
  // The original layout.
  EXPECT_TRUE(fs::exists(dir / "run/point_cloud/iteration_300/point_cloud.ply"));
  EXPECT_TRUE(fs::exists(dir / "run/cameras.json"));
  EXPECT_TRUE(fs::exists(dir / "run/config.json"));
  EXPECT_TRUE(fs::exists(dir / "run/input.ply"));
  EXPECT_TRUE(fs::exists(dir / "run/test/ours_300/renders/image000.png"));
  EXPECT_TRUE(fs::exists(dir / "run/test/ours_300/gt/image008.png"));
  const auto cams = nlohmann::json::parse(read_file(dir / "run/cameras.json"));
  EXPECT_EQ(cams.size(), 6u);
  const Gaussians saved = read_gaussians_ply(dir / "run/point_cloud/iteration_300/point_cloud.ply");
  EXPECT_EQ(saved.size(), trainer.model().size());
}

TEST(Trainer, SameSeedSameModelAndResumeIsBitIdentical) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "a", "dropgaussian", 40);
  cfg.densify_from = 10;
  cfg.densify_every = 10;
  cfg.opacity_reset_at = {25};
  cfg.checkpoint_iterations = {20};
  Trainer a(cfg);
  a.run();
  auto cfg_b = cfg;
  cfg_b.model_dir = (dir / "b").string();
  cfg_b.checkpoint_iterations = {};
  Trainer b(cfg_b);
  b.run();
  EXPECT_EQ(a.model().means, b.model().means);
  EXPECT_EQ(a.model().opacity_logits, b.model().opacity_logits);
  EXPECT_EQ(a.model().sh_rest, b.model().sh_rest);

  auto cfg_c = cfg_b;
  cfg_c.model_dir = (dir / "c").string();
  Trainer c(cfg_c, dir / "a/chkpnt20.bin");
  EXPECT_EQ(c.iteration(), 20);
  c.run();
  EXPECT_EQ(c.model().size(), a.model().size());
  EXPECT_EQ(c.model().means, a.model().means);
  EXPECT_EQ(c.model().log_scales, a.model().log_scales);
  EXPECT_EQ(c.model().opacity_logits, a.model().opacity_logits);
  EXPECT_EQ(c.model().sh_dc, a.model().sh_dc);

  auto cfg_d = cfg_b;
  cfg_d.model_dir = (dir / "d").string();
  cfg_d.seed = 2;
  Trainer d(cfg_d);
  d.run();
  EXPECT_NE(d.model().means, a.model().means);
}

// --stop-at N: the run stops after iteration N of its schedule with a checkpoint there, the test views
// scored and no results.json; resumed in place with the same options, it ends in the straight run's model.
TEST(Trainer, StopAtCutsTheScheduleAndResumesToTheStraightRunsModel) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "straight", "dropgaussian", 30);
  cfg.densify_from = 5;
  cfg.densify_every = 5;
  Trainer straight(cfg);
  straight.run();

  auto cfg_s = cfg;
  cfg_s.model_dir = (dir / "stopped").string();
  cfg_s.stop_at = 15;
  {
    Trainer stopped(cfg_s);
    stopped.run();
    EXPECT_EQ(stopped.iteration(), 15);
  }
  const fs::path out = dir / "stopped";
  EXPECT_TRUE(fs::is_regular_file(out / "chkpnt15.bin"));
  EXPECT_FALSE(fs::exists(out / "results.json"));
  std::ifstream log(out / "train_log.jsonl");
  std::string line;
  bool tested_at_stop = false;
  while (std::getline(log, line)) {
    const auto j = nlohmann::json::parse(line);
    if (j.value("event", "") == "test" && j.at("iteration") == 15) tested_at_stop = j.at("psnr").get<double>() > 5.0;
  }
  EXPECT_TRUE(tested_at_stop) << "no test event at the stop iteration";

  Trainer resumed(cfg_s, out / "chkpnt15.bin");
  EXPECT_EQ(resumed.iteration(), 15);
  resumed.run();
  EXPECT_EQ(resumed.iteration(), 30);
  expect_same_model(resumed.model(), straight.model());
  EXPECT_TRUE(fs::is_regular_file(out / "results.json"));

  auto bad = cfg_s;
  bad.stop_at = 31;
  EXPECT_EQ(test::error_of([&] { cfg_s.validate(); }), "");  // the stopped run's options are valid
  EXPECT_NE(test::error_of([&] { bad.validate(); }).find("--stop-at 31 is outside 0..30"), std::string::npos);
}

// Regularisers stacked on a method train, resume bit-identically (the noise has no state to lose) and
// change the model; the decay lowers the opacities.
TEST(Trainer, RegularisersTrainAndResumeBitIdentically) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "a", "dropgaussian", 20);
  cfg.densify_from = 5;
  cfg.densify_every = 5;
  cfg.opacity_reset_at = {};
  cfg.regularisers = {"opacity-noise", "opacity-decay"};
  cfg.opacity_decay_factor = 0.95;
  const auto runs = train_resume_and_train_plain(cfg, dir, 10);
  const Trainer& a = *runs.regularised;
  const Trainer& c = *runs.plain;
  const auto saved = nlohmann::json::parse(read_file(dir / "a/config.json"));
  EXPECT_EQ(saved["regularisers"], nlohmann::json({"opacity-noise", "opacity-decay"}));
  ASSERT_NE(c.model().means, a.model().means);
  const auto mean_opacity = [](const Gaussians& g) {
    double sum = 0;
    for (float l : g.opacity_logits) sum += 1.0 / (1.0 + std::exp(-static_cast<double>(l)));
    return sum / static_cast<double>(g.size());
  };
  // 0.95^14 ≈ 0.49 of decay over iterations 6–19, against what the gradients add back in 20 iterations.
  EXPECT_LT(mean_opacity(a.model()), 0.85 * mean_opacity(c.model()));
}

// The anisotropy term reaches the optimiser through parameter_terms(): over 20 iterations with the ratio set
// just above 1 (the initial Gaussians are isotropic), the regularised run's axis ratios stay well below the
// plain run's; the term is logged, and a resumed run trains bit for bit as the uninterrupted one.
TEST(Trainer, AnisotropyKeepsAxisRatiosDownAndResumesBitIdentically) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "a", "dropgaussian", 20);
  cfg.regularisers = {"anisotropy"};
  cfg.anisotropy_ratio = 1.01;
  cfg.anisotropy_lambda = 10.0;
  const auto runs = train_resume_and_train_plain(cfg, dir, 10);
  const auto mean_log_ratio = [](const Gaussians& g) {
    double sum = 0;
    for (std::size_t i = 0; i < g.size(); ++i) {
      const float* s = g.log_scales.data() + 3 * i;
      sum += std::max({s[0], s[1], s[2]}) - std::min({s[0], s[1], s[2]});
    }
    return sum / static_cast<double>(g.size());
  };
  const double regularised = mean_log_ratio(runs.regularised->model()), plain = mean_log_ratio(runs.plain->model());
  EXPECT_GT(plain, 0.02);  // the photometric gradients alone make the Gaussians anisotropic
  EXPECT_LT(regularised, 0.5 * plain);
  const std::string last = last_iteration_line(dir / "a/train_log.jsonl");
  ASSERT_FALSE(last.empty());
  EXPECT_TRUE(nlohmann::json::parse(last).contains("anisotropy")) << last;
}

// The scale-l1 term reaches the optimiser: over 20 iterations with a large weight the Gaussians end smaller
// than the plain run's; the term is logged, and a resumed run trains bit for bit as the uninterrupted one.
TEST(Trainer, ScaleL1ShrinksTheGaussiansAndResumesBitIdentically) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "a", "dropgaussian", 20);
  cfg.regularisers = {"scale-l1"};
  cfg.scale_l1_lambda = 100.0;
  const auto runs = train_resume_and_train_plain(cfg, dir, 10);
  const auto mean_log_scale = [](const Gaussians& g) {
    double sum = 0;
    for (float s : g.log_scales) sum += s;
    return sum / static_cast<double>(g.log_scales.size());
  };
  // Adam moves each log-scale by at most about the scale learning rate (0.005) per step: 20 steps pull the
  // regularised run's down by up to 0.1 where the photometric gradient does not hold them.
  EXPECT_LT(mean_log_scale(runs.regularised->model()), mean_log_scale(runs.plain->model()) - 0.03);
  const std::string last = last_iteration_line(dir / "a/train_log.jsonl");
  ASSERT_FALSE(last.empty());
  EXPECT_TRUE(nlohmann::json::parse(last).contains("scale_l1")) << last;
}

// The loss's gradient is L1's plus SSIM's: with λ_dssim = 0 the L1 gradient alone must train. (Until
// 2026-11-26 SSIM's backward wrote over the L1 gradient, so this run learned nothing.)
TEST(Trainer, TheL1GradientTrainsWithoutSsim) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "run", "3dgs", 30);
  cfg.init = "random";
  cfg.random_points = 2000;
  cfg.lambda_dssim = 0.0f;
  Trainer t(cfg);
  const std::vector<float> before = t.model().sh_dc;
  t.run();
  EXPECT_NE(t.model().sh_dc, before) << "no gradient reached the colours";
  std::ifstream log(dir / "run/train_log.jsonl");
  std::string line;
  std::vector<double> l1;
  while (std::getline(log, line)) {
    const auto j = nlohmann::json::parse(line);
    if (j.contains("l1")) l1.push_back(j["l1"].get<double>());
  }
  ASSERT_GE(l1.size(), 3u);
  EXPECT_LT(l1.back(), 0.9 * l1.front()) << "L1 " << l1.front() << " -> " << l1.back();
}

// --regularisers stereo-depth: the term is logged, resumes bit-identically (it keeps no state), and pulls the
// training views' rendered disparity towards the stereo depth maps of the run's geometry.
TEST(Trainer, StereoDepthPullsTheRenderTowardsTheStereoDepth) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "a", "dropgaussian", 40);
  cfg.init = "sparse";  // a cloud whose depth the stereo maps can still improve
  cfg.regularisers = {"stereo-depth"};
  cfg.stereo_depth_lambda = 0.5;
  const auto runs = train_resume_and_train_plain(cfg, dir, 20);
  std::ifstream log(dir / "a/train_log.jsonl");
  std::string line;
  int logged = 0;
  while (std::getline(log, line)) {
    const auto j = nlohmann::json::parse(line);
    if (j.contains("stereo_depth")) {
      EXPECT_GT(j["stereo_depth"].get<double>(), 0.0) << line;
      ++logged;
    }
  }
  EXPECT_GE(logged, 3);

  // The loss itself, on every training view of both models, against the maps the run used.
  auto rasterizer = render::make_cpu_rasterizer();
  const auto disparity_error = [&](const Trainer& t) {
    double sum = 0.0;
    for (int v : t.split().train) {
      const Camera& cam = t.scene().cameras[static_cast<std::size_t>(v)];
      const NpyArray map = read_npy(dir / "a/init/depth" / (fs::path(cam.image_name).stem().string() + ".npy"));
      Image depth(static_cast<int>(map.shape[1]), static_cast<int>(map.shape[0]), 1);
      for (std::size_t i = 0; i < map.values.size(); ++i) depth.pixels[i] = static_cast<float>(map.values[i]);
      depth = resize_area_nonzero(depth, cam.width, cam.height);
      const auto& out = rasterizer->forward(t.model(), nullptr, render::make_render_camera(cam), render::RenderOptions{});
      sum += disparity_l1_loss(out.depth.data(), out.alpha.data(), depth.pixels.data(), depth.pixels.size(), 0.5);
    }
    return sum;
  };
  const double with = disparity_error(*runs.regularised), without = disparity_error(*runs.plain);
  EXPECT_LT(with, 0.9 * without) << "with stereo-depth " << with << ", without " << without;
}

TEST(Trainer, D2gsDropsNearDenseGaussiansAndRuns) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "run", "d2gs", 12);
  cfg.dd_drop.rate_min = 0.3;  // make the drop visible in a short run
  Trainer t(cfg);
  double dropped = 0;
  for (int i = 0; i < 12; ++i) dropped += t.step().drop_fraction;
  EXPECT_GT(dropped / 12, 0.02);
  EXPECT_LT(dropped / 12, 0.3);
}

// A run that diverges stops with a one-line error at the iteration it happened, not with NaN models: an
// infinite position learning rate sends the means to infinity in the first Adam step.
TEST(Trainer, StopsWhenAParameterBecomesNonFinite) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "run", "3dgs", 5);
  cfg.lr.means = std::numeric_limits<float>::infinity();
  Trainer t(cfg);
  EXPECT_EQ(test::error_of([&] { t.step(); }), "iteration 1: a model parameter became non-finite; stopping");
}

TEST(Trainer, RefusesToOverwriteAndRejectsBadCheckpoints) {
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "user/notes.txt", "precious");
  EXPECT_THROW(Trainer(fern_config(dir / "user", "3dgs", 5)), Error);
  EXPECT_EQ(read_file(dir / "user/notes.txt"), "precious");
  write_file_atomic(dir / "bad.bin", "not a checkpoint");
  EXPECT_THROW(Trainer(fern_config(dir / "r", "3dgs", 5), dir / "bad.bin"), Error);
  auto cfg = fern_config(dir / "x", "3dgs", 5);
  cfg.resolution = 3;
  EXPECT_THROW(Trainer{cfg}, Error);
}

TEST(Trainer, RandomInitLiesInTheTrainingFrustaAndIsNotAnOracle) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "run", "3dgs", 3);
  cfg.init = "random";
  cfg.random_points = 3000;
  Trainer t(cfg);
  EXPECT_FALSE(t.init_is_oracle());
  ASSERT_EQ(t.model().size(), 3000u);
  const auto& m = t.model();
  std::size_t seen = 0;
  for (std::size_t i = 0; i < m.size(); ++i) {
    const glm::dvec3 x(m.means[i * 3], m.means[i * 3 + 1], m.means[i * 3 + 2]);
    for (int v : t.split().train) {
      const Camera& c = t.scene().cameras[static_cast<std::size_t>(v)];
      const glm::dvec3 p = c.R_world_to_cam * x + c.t_world_to_cam;
      const double u = c.fx * p.x / p.z + c.cx, w = c.fy * p.y / p.z + c.cy;
      if (p.z > 0 && u >= 0 && u <= c.width && w >= 0 && w <= c.height) {
        ++seen;
        break;
      }
    }
  }
  EXPECT_EQ(seen, m.size());  // every point is on a pixel ray of some training view
  // Its depth range is fern's LLFF bounds for the training views: poses_bounds.npy's near/far, which
  // imgs2poses computed as the 0.1/99.9 percentiles of each image's track depths (ours: of the points
  // that project into the image), so they agree closely but not exactly.
  const RandomInitRange range = random_init_depth_range(t.scene(), t.split().train, t.scene_extent());
  ASSERT_TRUE(range.from_dataset_points);
  const NpyArray bounds = read_npy(test::shared_data() / "nerf_llff_data/fern/poses_bounds.npy");
  ASSERT_EQ(bounds.shape.size(), 2u);
  double llff_near = 1e30, llff_far = 0;
  for (int v : t.split().train) {  // poses_bounds rows follow the sorted image names, as our cameras
    llff_near = std::min(llff_near, bounds.values[static_cast<std::size_t>(v) * 17 + 15]);
    llff_far = std::max(llff_far, bounds.values[static_cast<std::size_t>(v) * 17 + 16]);
  }
  EXPECT_NEAR(range.near / llff_near, 1.0, 0.08);  // measured: 16.98 … 81.51 against 17.54 … 78.72
  EXPECT_NEAR(range.far / llff_far, 1.0, 0.08);
  // Another seed draws another cloud.
  auto cfg2 = cfg;
  cfg2.model_dir = (dir / "run2").string();
  cfg2.seed = 5;
  EXPECT_NE(Trainer(cfg2).model().means, m.means);
}

TEST(Trainer, DefaultInitIsTheTrainingViewsGeometryWithStereoDepthPriors) {
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "run", "d2gs", 2);
  cfg.init_dense_method = TrainConfig{}.init_dense_method;  // the default stereo (PatchMatch)
  ASSERT_EQ(cfg.init, "dense");  // the default
  cfg.dafe.prior = "stereo";
  Trainer t(cfg);
  EXPECT_FALSE(t.init_is_oracle());
  const auto manifest = nlohmann::json::parse(read_file(dir / "run/init/init.json"));
  EXPECT_EQ(manifest["views"], nlohmann::json({1, 10, 19}));
  EXPECT_EQ(t.model().size(), manifest["dense_points"].get<std::size_t>());
  EXPECT_GT(t.model().size(), 10000u);
  EXPECT_EQ(read_point_cloud_ply(dir / "run/input.ply").size(), t.model().size());
  EXPECT_EQ(t.config().dafe.prior_kind, PriorKind::Depth);
  EXPECT_EQ(fs::path(t.config().dafe.prior), dir / "run/init/depth");
  t.step();
  t.step();
  EXPECT_EQ(t.iteration(), 2);
  // --init sparse: the triangulated SIFT points of the same (cached) geometry.
  auto sparse = fern_config(dir / "sparse", "3dgs", 1);
  sparse.init = "sparse";
  Trainer ts(sparse);
  EXPECT_FALSE(ts.init_is_oracle());
  EXPECT_GT(ts.model().size(), 100u);
  EXPECT_LT(ts.model().size(), 5000u);
}

TEST(Trainer, SavesAndTestsBeforeTheIterationsOpacityReset) {
  // As the original train.py: the model saved and scored at iteration t is the one before t's densification,
  // opacity reset and optimiser step. After a reset every opacity is <= 0.01 and the test PSNR collapses.
  const auto dir = test::scratch_dir();
  auto cfg = fern_config(dir / "run", "3dgs", 6);
  cfg.opacity_reset_at = {3};
  cfg.densify_from = 1000;
  cfg.save_iterations = {2, 3, 6};
  cfg.test_iterations = {2, 3, 4};
  Trainer trainer(cfg);
  trainer.run();
  const auto opacity_max = [&](int it) {
    const Gaussians g = read_gaussians_ply(dir / fmt::format("run/point_cloud/iteration_{}/point_cloud.ply", it));
    float mx = -1e30f;
    for (float logit : g.opacity_logits) mx = std::max(mx, logit);
    return 1.0f / (1.0f + std::exp(-mx));
  };
  EXPECT_GT(opacity_max(3), 0.05f);  // saved before the reset of iteration 3
  EXPECT_NEAR(opacity_max(3), opacity_max(2), 0.02f);
  EXPECT_LT(opacity_max(6), 0.012f);  // the reset shows from iteration 4 on (three small steps later)
  std::map<int, double> psnr;
  std::ifstream log(dir / "run/train_log.jsonl");
  for (std::string line; std::getline(log, line);) {
    const auto j = nlohmann::json::parse(line);
    if (j.value("event", "") == "test") psnr[j["iteration"].get<int>()] = j["psnr"].get<double>();
  }
  ASSERT_EQ(psnr.size(), 3u);
  EXPECT_NEAR(psnr[3], psnr[2], 0.5);  // the reset has not happened yet when iteration 3 is scored
  EXPECT_LT(psnr[4], psnr[3] - 0.5);   // it has when iteration 4 is
}

TEST(Trainer, RunFolderServesEvalAndImrCommands) {
  const auto dir = test::scratch_dir();
  const auto run = dir / "run";
  const auto r = test::run_cli(fmt::format(
      "-q train -s '{}' -m '{}' -r 8 --n-views 3 --iterations 4 --init random --random-points 2000",
      (test::shared_data() / "nerf_llff_data/fern").string(), run.string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  ASSERT_TRUE(fs::exists(run / "point_cloud/iteration_4/point_cloud.ply"));
  fs::remove(run / "results.json");
  const auto e = test::run_cli(fmt::format("-q eval -m '{}' --json", run.string()));
  ASSERT_EQ(e.exit_code, 0) << e.output;
  const auto results = nlohmann::json::parse(read_file(run / "results.json"));
  EXPECT_EQ(results["per_view"].size(), 3u);
  EXPECT_EQ(results["iteration"], 4);
  EXPECT_FALSE(results["init_is_oracle"].get<bool>());
  EXPECT_TRUE(fs::exists(run / "test/ours_4/renders/image016.png"));
  // The reference camera of IMR comes from the run's recorded scene.
  const auto m = test::run_cli(fmt::format("imr '{}' '{}' --samples 300", run.string(), run.string()));
  ASSERT_EQ(m.exit_code, 0) << m.output;
  EXPECT_NE(m.output.find("camera 0 (image000.png)"), std::string::npos) << m.output;
  // Bad input: a folder that is not a run.
  const auto bad = test::run_cli(fmt::format("eval -m '{}'", dir.string()));
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.output.find("config.json"), std::string::npos) << bad.output;
  // A scene whose test views are other images than the run's (here: the run's cameras.json renamed one) is
  // refused before anything is scored, and the run's results.json is left as it was.
  const std::string scored = read_file(run / "results.json");
  const std::string recorded_cameras = read_file(run / "cameras.json");
  const auto refused = [&](const std::function<void(nlohmann::json&)>& edit, const std::string& message) {
    auto cams = nlohmann::json::parse(recorded_cameras);
    for (auto& c : cams)
      if (c["global_index"] == 8) edit(c);
    write_file_atomic(run / "cameras.json", cams.dump());
    const auto other = test::run_cli(fmt::format("eval -m '{}'", run.string()));
    EXPECT_EQ(other.exit_code, 1) << other.output;
    EXPECT_NE(other.output.find("cameras.json: test view 8 " + message), std::string::npos) << other.output;
    EXPECT_EQ(read_file(run / "results.json"), scored);
  };
  refused([](nlohmann::json& c) { c["img_name"] = "image099"; },
          "was image image099 when the run was trained, it is image008 in");
  // The same names with other poses or sizes (another scene named alike, e.g. d2gs demo's): refused too.
  refused([](nlohmann::json& c) { c["position"][1] = c["position"][1].get<double>() + 0.01; },
          "(image008) was at (");
  refused([](nlohmann::json& c) { c["width"] = 63; }, "(image008) was 63x378 when the run was trained, it is 504x378");
  write_file_atomic(run / "cameras.json", recorded_cameras);
  // Nothing to score: a model without Gaussians, a run that records no test view.
  const auto ply = run / "point_cloud/iteration_4/point_cloud.ply";
  const std::string model = read_file(ply);
  write_gaussians_ply(ply, Gaussians{});
  const auto empty_model = test::run_cli(fmt::format("eval -m '{}'", run.string()));
  EXPECT_EQ(empty_model.exit_code, 1) << empty_model.output;
  EXPECT_NE(empty_model.output.find("point_cloud.ply: the model has no Gaussians"), std::string::npos) << empty_model.output;
  write_file_atomic(ply, model);
  const std::string config = read_file(run / "config.json");
  auto no_test = nlohmann::json::parse(config);
  no_test["split"]["test"] = nlohmann::json::array();
  write_file_atomic(run / "config.json", no_test.dump());
  const auto no_views = test::run_cli(fmt::format("eval -m '{}'", run.string()));
  EXPECT_EQ(no_views.exit_code, 1) << no_views.output;
  EXPECT_NE(no_views.output.find("config.json: records no test views"), std::string::npos) << no_views.output;
  auto odd_resolution = nlohmann::json::parse(config);
  odd_resolution["resolution"] = 3;
  write_file_atomic(run / "config.json", odd_resolution.dump());
  const auto three = test::run_cli(fmt::format("eval -m '{}'", run.string()));
  EXPECT_EQ(three.exit_code, 1) << three.output;
  EXPECT_NE(three.output.find((run / "config.json").string() + ": key 'resolution' must be 1, 2, 4 or 8 (got 3)"),
            std::string::npos)
      << three.output;
  write_file_atomic(run / "config.json", config);
  EXPECT_EQ(read_file(run / "results.json"), scored);
  // --iteration counts from 1; a folder whose number no int holds is not a saved iteration.
  EXPECT_NE(test::run_cli(fmt::format("eval -m '{}' --iteration 0", run.string())).exit_code, 0);
  fs::create_directories(run / "point_cloud/iteration_99999999999");
  write_file_atomic(run / "point_cloud/iteration_99999999999/point_cloud.ply", model);
  const auto huge = test::run_cli(fmt::format("-q eval -m '{}' --json", run.string()));
  EXPECT_EQ(huge.exit_code, 0) << huge.output;
  EXPECT_EQ(nlohmann::json::parse(read_file(run / "results.json"))["iteration"], 4);
}

// The image source (PIL's resize of the largest folder by default) is recorded and eval scores against the
// source the run was trained on (or the one asked for): the renders are the same, the ground truth is not.
// A config.json without the key (a run from before the option) was trained on images_R/ and is scored so.
TEST(Trainer, ImageSourceIsRecordedAndEvalScoresAgainstIt) {
  const auto dir = test::scratch_dir();
  const auto run = dir / "run";
  const auto r = test::run_cli(fmt::format(
      "-q train -s '{}' -m '{}' -r 8 --n-views 3 --iterations 4 --init random --random-points 2000 "
      "--alpha-clamp-grad pass-through",
      (test::shared_data() / "nerf_llff_data/fern").string(), run.string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const auto cfg = nlohmann::json::parse(read_file(run / "config.json"));
  EXPECT_EQ(cfg["image_source"], "largest");
  EXPECT_EQ(cfg["images_folder"], "images_4");
  EXPECT_EQ(cfg["alpha_clamp_grad"], "pass-through");
  const auto trained = nlohmann::json::parse(read_file(run / "results.json"));
  EXPECT_EQ(trained["image_source"], "largest");
  const auto e = test::run_cli(fmt::format("-q eval -m '{}' --json", run.string()));
  ASSERT_EQ(e.exit_code, 0) << e.output;
  const auto same = nlohmann::json::parse(read_file(run / "results.json"));
  EXPECT_EQ(same["image_source"], "largest");
  EXPECT_NEAR(same["mean"]["PSNR"].get<double>(), trained["mean"]["PSNR"].get<double>(), 1e-9);
  const auto f = test::run_cli(fmt::format("-q eval -m '{}' --json --image-source folder", run.string()));
  ASSERT_EQ(f.exit_code, 0) << f.output;
  const auto other = nlohmann::json::parse(read_file(run / "results.json"));
  EXPECT_EQ(other["image_source"], "folder");
  EXPECT_EQ(other["images_folder"], "images_8");
  EXPECT_NE(other["mean"]["PSNR"].get<double>(), trained["mean"]["PSNR"].get<double>());
  EXPECT_NEAR(other["mean"]["PSNR"].get<double>(), trained["mean"]["PSNR"].get<double>(), 1.0);
  const auto bad = test::run_cli(fmt::format("-q eval -m '{}' --image-source pil", run.string()));
  EXPECT_NE(bad.exit_code, 0);
  auto older = cfg;
  older.erase("image_source");
  write_file_atomic(run / "config.json", older.dump(2));
  const auto o = test::run_cli(fmt::format("-q eval -m '{}' --json", run.string()));
  ASSERT_EQ(o.exit_code, 0) << o.output;
  const auto as_before = nlohmann::json::parse(read_file(run / "results.json"));
  EXPECT_EQ(as_before["image_source"], "folder");
  EXPECT_EQ(as_before["mean"]["PSNR"].get<double>(), other["mean"]["PSNR"].get<double>());
}

TEST(TrainConfig, JsonRoundTripAndUnknownKeys) {
  TrainConfig c;
  c.source = "s";
  c.model_dir = "m";
  c.method = "d2gs";
  c.image_source = ImageSource::Folder;    // not the default
  c.alpha_clamp_pass_through = true;       // not the default
  c.dd_drop.weight_depth = 0.7;
  c.dafe.loss_form = DafeLossForm::Paper;  // not the default
  c.opacity_reset_at = {100};
  nlohmann::json j;
  to_json(j, c);
  TrainConfig d;
  update_from_json(d, j);
  nlohmann::json k;
  to_json(k, d);
  EXPECT_EQ(j, k);
  EXPECT_THROW(update_from_json(d, nlohmann::json{{"iteratons", 5}}), Error);
  EXPECT_THROW(update_from_json(d, nlohmann::json{{"iterations", "many"}}), Error);
  EXPECT_THROW(update_from_json(d, nlohmann::json{{"method", "nerf"}}), Error);
  EXPECT_THROW(update_from_json(d, nlohmann::json{{"image_source", "pil"}}), Error);
  EXPECT_THROW(update_from_json(d, nlohmann::json{{"alpha_clamp_grad", "none"}}), Error);
}

}  // namespace
}  // namespace d2gs
