// End to end on fern, 3 views at 504×378: point counts, accuracy against the dataset's all-view SfM
// cloud (used here only to measure), determinism, the no-test-image rule, the files of `d2gs init`,
// the published layout reused by d2gs train, and the one-line error when the views do not overlap.
#include <unistd.h>

#include <gtest/gtest.h>

#include <set>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/file_lock.hpp"
#include "d2gs/core/error.hpp"
#include "d2gs/core/npy.hpp"
#include "d2gs/geometry/depth_preview.hpp"
#include "d2gs/geometry/training_geometry.hpp"
#include "d2gs/model/ply.hpp"
#include "d2gs/scene/split.hpp"
#include "synthetic_fixture.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

fs::path fern() { return test::shared_data() / "nerf_llff_data/fern"; }

struct Fern3 {
  Scene scene;
  Split split;
};

Fern3 fern3() {
  SceneLoadOptions lo;
  lo.resolution = 8;
  Fern3 f{load_scene(fern(), lo), {}};
  SplitOptions so;
  so.n_views = 3;
  f.split = make_split(f.scene, so);
  return f;
}

using test::ImageReads;

TEST(TrainingGeometry, Fern3ViewsPointsAccuracyAndOnlyTrainingImages) {
  const Fern3 f = fern3();
  ASSERT_EQ(f.split.train, (std::vector<int>{1, 10, 19}));
  TrainingGeometry g;
  std::set<fs::path> read;
  {
    ImageReads reads;
    g = build_training_geometry(f.scene, f.split.train, TrainingGeometryOptions{});
    read.insert(reads.paths.begin(), reads.paths.end());
    EXPECT_EQ(reads.paths.size(), 3u);
  }
  // The no-test-image rule: exactly the training views' files were decoded.
  std::set<fs::path> train;
  for (int v : f.split.train) train.insert(f.scene.cameras[static_cast<std::size_t>(v)].image_path);
  EXPECT_EQ(read, train);
  for (int v : f.split.test) EXPECT_EQ(read.count(f.scene.cameras[static_cast<std::size_t>(v)].image_path), 0u);

  const CloudAccuracy sparse = cloud_accuracy(g.sparse, f.scene.sfm_points);
  const CloudAccuracy dense = cloud_accuracy(g.dense, f.scene.sfm_points);
  std::printf("fern 3 views: %zu sparse points (mean reprojection %.3f px, median distance to the oracle %.4f of the "
              "extent), %zu dense points (%.4f)\n",
              g.sparse.size(), g.mean_reprojection_px(), sparse.median_fraction(), g.dense.size(),
              dense.median_fraction());
  EXPECT_GT(g.sparse.size(), 150u);
  EXPECT_LT(g.mean_reprojection_px(), 0.6);
  EXPECT_LT(sparse.median_fraction(), 0.006);
  EXPECT_GT(g.dense.size(), 10000u);  // every 4th pixel of each axis
  EXPECT_LT(dense.median_fraction(), 0.012);
  // A cloud that is not on the surfaces fails the same measure (the bound can fail).
  PointCloud shifted = g.sparse;
  for (auto& p : shifted.positions) p += glm::vec3(0.0f, 0.0f, 0.05f * static_cast<float>(sparse.reference_extent));
  EXPECT_GT(cloud_accuracy(shifted, f.scene.sfm_points).median_fraction(), 0.006);
  ASSERT_EQ(g.depth.size(), 3u);
  for (const auto& d : g.depth) EXPECT_GT(static_cast<double>(d.valid_count()) / static_cast<double>(d.depth.size()), 0.2);
}

// The depth pictures: one inverse-depth range for all views (2nd–98th percentile), near red, far blue
// (turbo's ends), no depth black, equal depths equal colours across views.
TEST(DepthPreview, NearIsRedFarIsBlueNoDepthIsBlack) {
  DepthMap a{100, 1, std::vector<float>(100)}, b{2, 1, {0.0f, 0.0f}};
  for (int x = 0; x < 100; ++x) a.depth[static_cast<std::size_t>(x)] = x == 50 ? 0.0f : 1.0f + 0.09f * static_cast<float>(x);
  const auto range = inverse_depth_range({a, b});
  // 99 depths: the 98th percentile of 1/z is the third nearest (x = 2), the 2nd the second farthest (x = 98).
  EXPECT_NEAR(range.second, 1.0 / (1.0 + 0.09 * 2), 1e-6);
  EXPECT_NEAR(range.first, 1.0 / (1.0 + 0.09 * 98), 1e-6);
  const Image p = depth_preview(a, range);
  ASSERT_EQ(p.width, 100);
  ASSERT_EQ(p.channels, 3);
  EXPECT_GT(p.at(0, 0, 0), 0.4f);   // nearest: turbo's dark-red end
  EXPECT_LT(p.at(0, 0, 2), 0.1f);
  EXPECT_LT(p.at(99, 0, 0), 0.25f);  // farthest: turbo's dark-blue end (48, 18, 59)
  EXPECT_GT(p.at(99, 0, 2), p.at(99, 0, 0));
  EXPECT_EQ(p.at(99, 0, 2), p.at(98, 0, 2));  // clamped beyond the range
  for (int k = 0; k < 3; ++k) EXPECT_EQ(p.at(50, 0, k), 0.0f);  // no depth
  // The same depth in another map gets the same colour.
  DepthMap c{1, 1, {a.depth[20]}};
  const Image q = depth_preview(c, range);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(q.at(0, 0, k), p.at(20, 0, k));
  EXPECT_EQ(inverse_depth_range({b}), std::make_pair(0.0, 0.0));
  const Image black = depth_preview(b, {0.0, 0.0});
  for (float v : black.pixels) EXPECT_EQ(v, 0.0f);
}

TEST(TrainingGeometry, SameSeedSameClouds) {
  const Fern3 f = fern3();
  TrainingGeometryOptions o;
  o.max_dense_points = 5000;  // exercise the seeded subsample
  o.seed = 4;
  const auto a = build_training_geometry(f.scene, f.split.train, o);
  const auto b = build_training_geometry(f.scene, f.split.train, o);
  ASSERT_EQ(a.dense.size(), 5000u);
  EXPECT_EQ(a.sparse.positions, b.sparse.positions);
  EXPECT_EQ(a.dense.positions, b.dense.positions);
  EXPECT_EQ(a.dense.colors, b.dense.colors);
}

TEST(TrainingGeometry, CachedGeometryIsReusedOnlyWhenItMatches) {
  const auto dir = test::scratch_dir();
  const Fern3 f = fern3();
  TrainingGeometryOptions o;
  o.dense = false;
  const auto built = obtain_training_geometry(f.scene, f.split.train, o, {dir / "none", dir / "a"}, dir / "a");
  EXPECT_EQ(built.dir, dir / "a");
  EXPECT_FALSE(built.has_dense);
  {
    ImageReads reads;
    const auto again = obtain_training_geometry(f.scene, f.split.train, o, {dir / "a"}, dir / "b");
    EXPECT_EQ(again.dir, dir / "a");
    EXPECT_TRUE(reads.paths.empty());  // nothing recomputed
  }
  EXPECT_FALSE(fs::exists(dir / "b"));
  // Other views, or other options: not a match.
  EXPECT_FALSE(find_training_geometry(dir / "a", f.scene, {1, 10}, o));
  TrainingGeometryOptions other = o;
  other.triangulation.min_angle_deg = 2.0;
  EXPECT_FALSE(find_training_geometry(dir / "a", f.scene, f.split.train, other));
  EXPECT_TRUE(find_training_geometry(dir / "a", f.scene, f.split.train, o));
  // The same names and options, but another image file or a moved camera (a scene regenerated or
  // re-processed): not a match either.
  Fern3 moved = fern3();
  moved.scene.cameras[10].t_world_to_cam.x += 0.01;
  EXPECT_FALSE(find_training_geometry(dir / "a", moved.scene, f.split.train, o));
  Fern3 other_image = fern3();
  other_image.scene.cameras[10].image_path = f.scene.cameras[11].image_path;
  EXPECT_FALSE(find_training_geometry(dir / "a", other_image.scene, f.split.train, o));
  // A manifest from before the fingerprints is taken on its names, as then.
  auto manifest = nlohmann::json::parse(read_file(dir / "a/init.json"));
  ASSERT_TRUE(manifest.contains("view_fingerprints"));
  manifest.erase("view_fingerprints");
  write_file_atomic(dir / "a/init.json", manifest.dump());
  EXPECT_TRUE(find_training_geometry(dir / "a", moved.scene, f.split.train, o));
}

TEST(TrainingGeometry, ViewsThatDoNotOverlapGiveAOneLineError) {
  Fern3 f = fern3();
  // Turn view 10 around: it now looks away from what views 1 and 19 see.
  Camera& c = f.scene.cameras[10];
  const glm::dmat3 flip(glm::dvec3(-1, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, -1));
  const glm::dvec3 centre = c.center_world();
  c.R_world_to_cam = flip * c.R_world_to_cam;
  c.t_world_to_cam = -c.R_world_to_cam * centre;
  try {
    (void)build_training_geometry(f.scene, {10, 19}, TrainingGeometryOptions{});
    FAIL() << "expected an error";
  } catch (const Error& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("do not overlap enough"), std::string::npos) << m;
    EXPECT_NE(m.find(fern().string()), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos);
  }
}

TEST(TrainingGeometry, InitCommandWritesTheLayoutAndTheTrainerLoadsItsDepthPriors) {
  const auto dir = test::scratch_dir();
  const auto r = test::run_cli(
      fmt::format("init -s '{}' --n-views 3 -r 8 -o '{}' --oracle-accuracy --dense-method sgbm", fern().string(), (dir / "init").string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("SIFT"), std::string::npos) << r.output;
  const auto m = nlohmann::json::parse(read_file(dir / "init/init.json"));
  EXPECT_EQ(m["views"], nlohmann::json({1, 10, 19}));
  const PointCloud sparse = read_point_cloud_ply(dir / "init/sparse/points3D.ply");
  const PointCloud dense = read_point_cloud_ply(dir / "init/dense/fused.ply");
  EXPECT_EQ(sparse.size(), m["sparse_points"].get<std::size_t>());
  EXPECT_EQ(dense.size(), m["dense_points"].get<std::size_t>());
  for (const char* name : {"image001", "image010", "image019"}) {
    const NpyArray d = read_npy(dir / "init/depth" / (std::string(name) + ".npy"));
    EXPECT_EQ(d.shape, (std::vector<std::size_t>{378, 504}));
    EXPECT_TRUE(fs::exists(dir / "init/depth" / (std::string(name) + "_valid.png")));
  }
  EXPECT_FALSE(fs::exists(dir / "init/depth/image000.npy"));  // test view
  const auto acc = nlohmann::json::parse(read_file(dir / "init/oracle_accuracy.json"));
  EXPECT_LT(acc["sparse"]["median_fraction"].get<double>(), 0.006);
  // Bad input: one line.
  const auto bad = test::run_cli(fmt::format("init -s '{}' --n-views 1 -r 8 -o '{}'", fern().string(), (dir / "x").string()));
  EXPECT_EQ(bad.exit_code, 1);
  EXPECT_NE(bad.output.find("d2gs: error: "), std::string::npos) << bad.output;
  EXPECT_NE(bad.output.find("at least 2 views"), std::string::npos) << bad.output;
  // Options that cannot give a geometry: one line before any work (they were taken, or failed after it with
  // "views do not overlap enough", or wrote an empty fused cloud).
  for (const auto& [args, message] : std::vector<std::pair<std::string, std::string>>{
           {"--fusion-tolerance -1", "option --fusion-tolerance must be in (0, 1] (got -1)"},
           {"--fusion-tolerance nan", "init: option --fusion-tolerance: 'nan' is not a finite number"},
           {"--max-features 0", "option --max-features must be ≥ 1 (got 0)"},
           {"--match-ratio 5", "option --match-ratio must be in (0, 1] (got 5)"},
           {"--min-angle 200", "option --min-angle must be in [0, 90) degrees (got 200)"},
           {"--stereo-neighbors 0", "option --stereo-neighbors must be ≥ 1 (got 0)"},
           {"--sift-contrast -1", "option --sift-contrast must be in (0, 1] (got -1)"}}) {
    const auto opt = test::run_cli(fmt::format("init -s '{}' --n-views 3 -r 8 -o '{}' --dense-method sgbm {}",
                                               fern().string(), (dir / "opt").string(), args));
    EXPECT_EQ(opt.exit_code, 1) << args << "\n" << opt.output;
    EXPECT_NE(opt.output.find("d2gs: error: " + message), std::string::npos) << args << "\n" << opt.output;
    EXPECT_EQ(opt.output.find("SIFT"), std::string::npos) << args << ": the work was done first";
  }
  const auto compare_sparse = test::run_cli(fmt::format("init -s '{}' --n-views 3 -r 8 -o '{}' --no-dense --compare-cloud '{}'",
                                                        fern().string(), (dir / "opt").string(),
                                                        (dir / "init/dense/fused.ply").string()));
  EXPECT_EQ(compare_sparse.exit_code, 1) << compare_sparse.output;
  EXPECT_NE(compare_sparse.output.find("--no-dense does not make"), std::string::npos) << compare_sparse.output;
  const auto sparse_stride = test::run_cli(fmt::format("init -s '{}' --n-views 3 -r 8 -o '{}' --dense-method sgbm "
                                                       "--dense-stride 1000000", fern().string(), (dir / "opt").string()));
  EXPECT_EQ(sparse_stride.exit_code, 1) << sparse_stride.output;
  EXPECT_NE(sparse_stride.output.find("fused no point"), std::string::npos) << sparse_stride.output;
  EXPECT_FALSE(fs::exists(dir / "opt/init.json"));
  // A write that fails part-way (each file limited to 300 kB: the sparse cloud fits, the depth maps do not,
  // as on a full disk) takes back what it wrote, so that the next init into the folder is not refused.
  ASSERT_LT(fs::file_size(dir / "init/sparse/points3D.ply"), 300000u);
  const auto partial = test::run_cli_with_file_size_limit(
      fmt::format("init -s '{}' --n-views 3 -r 8 -o '{}' --dense-method sgbm", fern().string(), (dir / "partial").string()),
      300000);
  EXPECT_EQ(partial.exit_code, 1) << partial.output;
  EXPECT_NE(partial.output.find(": write failed"), std::string::npos) << partial.output;
  EXPECT_FALSE(fs::exists(dir / "partial")) << partial.output;
  // While another init works in the folder (its lock held here), a second one is refused before any work.
  {
    fs::create_directories(dir / "busy");
    const auto held = FileLock::try_acquire(dir / "busy/.d2gs-init.lock");
    ASSERT_TRUE(held);
    const auto busy = test::run_cli(fmt::format("init -s '{}' --n-views 3 -r 8 -o '{}' --dense-method sgbm",
                                                fern().string(), (dir / "busy").string()));
    EXPECT_EQ(busy.exit_code, 1) << busy.output;
    EXPECT_NE(busy.output.find((dir / "busy").string() + ": another d2gs init (process " + std::to_string(::getpid()) +
                               ") is writing into this folder"),
              std::string::npos)
        << busy.output;
    EXPECT_EQ(busy.output.find("SIFT"), std::string::npos) << "the work was done first:\n" << busy.output;
  }
  EXPECT_FALSE(fs::exists(dir / "init/.d2gs-init.lock"));  // a finished init leaves no lock file
  // The same folder again: refused before any work, the first geometry left as it was.
  const std::string cloud = read_file(dir / "init/dense/fused.ply");
  const auto again = test::run_cli(
      fmt::format("init -s '{}' --n-views 3 -r 8 -o '{}' --dense-method patchmatch", fern().string(), (dir / "init").string()));
  EXPECT_EQ(again.exit_code, 1) << again.output;
  EXPECT_NE(again.output.find((dir / "init").string() + ": already holds a training geometry (init.json)"),
            std::string::npos)
      << again.output;
  EXPECT_EQ(again.output.find("SIFT"), std::string::npos) << "the work was done first:\n" << again.output;
  EXPECT_EQ(read_file(dir / "init/dense/fused.ply"), cloud);
  // A folder holding files of the names its depth maps take (the demo's true depth in SCENE/depth/) is
  // refused too, before the work.
  fs::create_directories(dir / "scene_like/depth");
  write_file_atomic(dir / "scene_like/depth/image010.npy", "the user's");
  const auto depth = test::run_cli(
      fmt::format("init -s '{}' --n-views 3 -r 8 -o '{}' --dense-method sgbm", fern().string(), (dir / "scene_like").string()));
  EXPECT_EQ(depth.exit_code, 1) << depth.output;
  EXPECT_NE(depth.output.find((dir / "scene_like/depth/image010.npy").string() + ": exists"), std::string::npos)
      << depth.output;
  EXPECT_EQ(read_file(dir / "scene_like/depth/image010.npy"), "the user's");
  // The depth maps as DAFE priors of a short D²GS run that initialises from the same cloud.
  const auto t = test::run_cli(fmt::format(
      "-q train -s '{}' -m '{}' -r 8 --n-views 3 --iterations 2 --method d2gs --init '{}' --dafe-prior '{}' "
      "--dafe-prior-kind depth",
      fern().string(), (dir / "run").string(), (dir / "init/dense/fused.ply").string(), (dir / "init/depth").string()));
  ASSERT_EQ(t.exit_code, 0) << t.output;
  const auto cfg = nlohmann::json::parse(read_file(dir / "run/config.json"));
  EXPECT_EQ(cfg["dafe_prior_kind"], "depth");
  EXPECT_FALSE(cfg["init_is_oracle"].get<bool>());
}

TEST(TrainingGeometry, InitWritesThePublishedLayoutAndTrainReusesIt) {
  // A copy of fern (1/8 images, poses, SfM model) so that SCENE/3_views is written into scratch, not the shared data.
  const auto dir = test::scratch_dir();
  const fs::path scene = dir / "fern";
  fs::create_directories(scene);
  for (const char* item : {"images_8", "sparse", "poses_bounds.npy"})
    fs::copy(fern() / item, scene / item, fs::copy_options::recursive);
  const auto r = test::run_cli(fmt::format("init -s '{}' --n-views 3 -r 8", scene.string()));
  ASSERT_EQ(r.exit_code, 0) << r.output;
  // Progress and timing of every step.
  for (const char* step : {"init: read 3 training views", "init: SIFT:", "init: matching 3 pairs", " tracks (",
                           "init: PatchMatch stereo on 3 views", "init: fusion:"})
    EXPECT_NE(r.output.find(step), std::string::npos) << step << "\n" << r.output;
  const fs::path views = scene / "3_views";
  for (const char* file : {"init.json", "sparse/points3D.ply", "dense/fused.ply", "depth/image001.npy",
                           "depth/image010_valid.png", "depth/image010_depth.png", "depth/image019.npy"})
    EXPECT_TRUE(fs::exists(views / file)) << file;
  const auto m = nlohmann::json::parse(read_file(views / "init.json"));
  for (const char* step : {"read images", "sift", "matching", "triangulation", "stereo", "fusion"})
    EXPECT_TRUE(m["timings_s"].contains(step)) << step;
  // d2gs train without --init: the default init is this geometry, reused (not rebuilt into MODEL/init).
  const auto t = test::run_cli(fmt::format("train -s '{}' -m '{}' -r 8 --n-views 3 --iterations 1 --quiet",
                                           scene.string(), (dir / "run").string()));
  ASSERT_EQ(t.exit_code, 0) << t.output;
  EXPECT_NE(t.output.find("reusing the training-view geometry in " + views.string()), std::string::npos) << t.output;
  EXPECT_FALSE(fs::exists(dir / "run/init"));
  EXPECT_EQ(read_point_cloud_ply(dir / "run/input.ply").size(), m["dense_points"].get<std::size_t>());
  const auto cfg = nlohmann::json::parse(read_file(dir / "run/config.json"));
  EXPECT_EQ(cfg["init"], "dense");
  EXPECT_FALSE(cfg["init_is_oracle"].get<bool>());
}

// An output folder under a file used to fail with "internal: filesystem error" after the stereo work.
TEST(TrainingGeometry, InitOutputUnderAFileFailsBeforeTheWork) {
  const auto dir = test::scratch_dir();
  write_file_atomic(dir / "file", "x");
  const auto r = test::run_cli(fmt::format("init -s '{}' --n-views 3 -r 8 -o '{}'", fern().string(),
                                           (dir / "file/geometry").string()));
  EXPECT_EQ(r.exit_code, 1) << r.output;
  EXPECT_NE(r.output.find((dir / "file/geometry").string() + ": cannot write here: " + (dir / "file").string() +
                          " is a file, not a folder"),
            std::string::npos)
      << r.output;
  EXPECT_EQ(r.output.find("sparse points"), std::string::npos) << "the work was done first:\n" << r.output;
}

}  // namespace
}  // namespace d2gs
