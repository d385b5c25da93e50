// Stereo and fusion on the built-in synthetic scene, whose true depth is known at every pixel; and the
// whole training-view pipeline on it (sparse points on the true surfaces).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include <fmt/format.h>

#include "d2gs/demo/synthetic_scene.hpp"
#include "d2gs/geometry/fusion.hpp"
#include "d2gs/geometry/stereo.hpp"
#include "d2gs/geometry/training_geometry.hpp"
#include "synthetic_fixture.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {
namespace fs = std::filesystem;

const SyntheticScene& scene() { return test::small_synthetic_scene(); }

// Depth errors measured as disparity errors in pixels, f·B·|1/z − 1/z_true| for a baseline B: the unit
// in which stereo errs (a tenth of a pixel is 4 % of depth on the far backdrop, 0.2 % up close).
struct DepthErrors {
  double median_disparity_px = 1e9;
  double median_signed_px = 1e9;   // bias
  double valid_fraction = 0.0;
};

DepthErrors compare(const DepthMap& d, const std::vector<float>& truth, double f, double baseline) {
  std::vector<double> err, signed_err;
  for (std::size_t i = 0; i < truth.size(); ++i)
    if (d.depth[i] > 0.0f) {
      const double e = f * baseline * (1.0 / d.depth[i] - 1.0 / truth[i]);
      err.push_back(std::abs(e));
      signed_err.push_back(e);
    }
  DepthErrors out;
  if (err.empty()) return out;
  std::sort(err.begin(), err.end());
  std::sort(signed_err.begin(), signed_err.end());
  out.median_disparity_px = err[err.size() / 2];
  out.median_signed_px = signed_err[signed_err.size() / 2];
  out.valid_fraction = static_cast<double>(err.size()) / static_cast<double>(truth.size());
  return out;
}

void expect_pair_recovers_depth(int va, int vb) {
  const auto& cams = scene().cameras();
  const Camera &a = cams[static_cast<std::size_t>(va)], &b = cams[static_cast<std::size_t>(vb)];
  const auto r = stereo_pair_depth(a, scene().render(a), b, scene().render(b), 2.0, 45.0);
  for (const auto& [map, cam] : {std::pair{&r.depth_a, &a}, std::pair{&r.depth_b, &b}}) {
    const auto e = compare(*map, scene().depth_map(*cam), cam->fx, r.baseline);
    std::printf("stereo %d/%d, view %s: %.1f %% valid, median disparity error %.3f px (signed %.3f px)\n", va, vb,
                cam->image_name.c_str(), 100 * e.valid_fraction, e.median_disparity_px, e.median_signed_px);
    EXPECT_GT(e.valid_fraction, 0.5);
    EXPECT_LT(e.median_disparity_px, 0.35);
    EXPECT_LT(std::abs(e.median_signed_px), 0.2);  // a half-pixel convention slip would be 0.5
  }
}

TEST(Stereo, HorizontalPairRecoversTheTrueDepth) { expect_pair_recovers_depth(0, 2); }
TEST(Stereo, ReversedPairGivesTheSameDepth) { expect_pair_recovers_depth(2, 0); }
// Cameras of one grid column (5 per row): a vertical baseline, handled by transposing the pair.
TEST(Stereo, VerticalPairRecoversTheTrueDepth) { expect_pair_recovers_depth(1, 11); }

TEST(Fusion, MergeKeepsAgreeingCandidates) {
  DepthMap a{2, 1, {10.0f, 10.0f}}, b{2, 1, {10.1f, 0.0f}}, c{2, 1, {20.0f, 0.0f}};
  const auto m = merge_depth_candidates({&a, &b, &c}, 0.02);
  EXPECT_NEAR(m.depth[0], 10.05f, 1e-4);  // 20 disagrees with the median 10.1
  EXPECT_EQ(m.depth[1], 10.0f);           // a single candidate
  DepthMap d{1, 1, {10.0f}}, e{1, 1, {30.0f}};
  EXPECT_EQ(merge_depth_candidates({&d, &e}, 0.02).depth[0], 0.0f);  // no majority: no depth
}

TEST(Fusion, CrossViewConsistencyRemovesWrongDepths) {
  const auto& cams = scene().cameras();
  const std::vector<const Camera*> two = {&cams[0], &cams[2]};
  std::vector<DepthMap> maps(2);
  for (std::size_t i = 0; i < 2; ++i) {
    maps[i].width = two[i]->width;
    maps[i].height = two[i]->height;
    maps[i].depth = scene().depth_map(*two[i]);
  }
  // Corrupt a block of view 0 by 10 %: those pixels no longer agree with view 1.
  for (int y = 50; y < 100; ++y)
    for (int x = 100; x < 150; ++x) maps[0].depth[static_cast<std::size_t>(y) * maps[0].width + x] *= 1.1f;
  const auto kept = filter_consistent_depths(two, maps, FusionOptions{});
  std::size_t corrupted_kept = 0, clean_kept = 0, clean = 0;
  for (int y = 0; y < maps[0].height; ++y)
    for (int x = 0; x < maps[0].width; ++x) {
      const bool corrupt = y >= 50 && y < 100 && x >= 100 && x < 150;
      const bool k = kept[0].at(x, y) > 0.0f;
      if (corrupt) corrupted_kept += k;
      else clean += 1, clean_kept += k;
    }
  EXPECT_LT(corrupted_kept, 25u);  // of 2500 (occlusion edges may agree by chance)
  EXPECT_GT(static_cast<double>(clean_kept) / static_cast<double>(clean), 0.8);
}

TEST(Fusion, BackProjectionLandsOnTheTracedSurface) {
  const Camera& c = scene().cameras()[4];
  const Image image = scene().render(c);
  DepthMap d{c.width, c.height, scene().depth_map(c)};
  const PointCloud cloud = fuse_depth_maps({&c}, {&image}, {d}, 10);
  EXPECT_EQ(cloud.size(), static_cast<std::size_t>(((c.width - 5 + 9) / 10) * ((c.height - 5 + 9) / 10)));
  const SyntheticHit hit = scene().trace(c, 25.5, 35.5);  // pixel (25, 35): stride 10 from 5
  const std::size_t row_points = static_cast<std::size_t>((c.width - 5 + 9) / 10);
  EXPECT_LT(glm::length(glm::dvec3(cloud.positions[3 * row_points + 2]) - hit.position), 1e-4 * hit.depth);
}

TEST(TrainingGeometry, SyntheticSceneSparseAndDenseLieOnTheTrueSurfaces) {
  const Scene s = load_scene(test::small_synthetic_dir());
  const std::vector<int> views = {1, 3, 12};
  TrainingGeometryOptions o;
  o.fusion.pixel_stride = 2;
  const TrainingGeometry g = build_training_geometry(s, views, o);
  ASSERT_GT(g.sparse.size(), 50u);
  EXPECT_LT(g.mean_reprojection_px(), 0.5);
  // Depth of each sparse point in view 1 against the traced depth at its pixel.
  const Camera& c = s.cameras[1];
  const double f = c.fx, baseline = glm::length(s.cameras[1].center_world() - s.cameras[3].center_world());
  std::vector<double> err;
  for (const auto& p : g.sparse.positions) {
    const glm::dvec3 q = c.R_world_to_cam * glm::dvec3(p) + c.t_world_to_cam;
    ASSERT_GT(q.z, 0.0);  // cheirality
    const double u = c.fx * q.x / q.z + c.cx, v = c.fy * q.y / q.z + c.cy;
    if (u < 0 || v < 0 || u >= c.width || v >= c.height) continue;
    const double truth = scene().trace(c, u, v).depth;  // at the point's own pixel position
    err.push_back(f * baseline * std::abs(1.0 / q.z - 1.0 / truth));
  }
  std::sort(err.begin(), err.end());
  ASSERT_FALSE(err.empty());
  const auto e = compare(g.depth[0], scene().depth_map(c), f, baseline);
  std::printf("synthetic: %zu sparse points, median disparity error %.3f px; %zu dense points, depth map of view 1: "
              "%.1f %% valid, median disparity error %.3f px\n",
              g.sparse.size(), err[err.size() / 2], g.dense.size(), 100 * e.valid_fraction, e.median_disparity_px);
  EXPECT_LT(err[err.size() / 2], 0.4);
  ASSERT_EQ(g.depth.size(), 3u);
  EXPECT_LT(e.median_disparity_px, 0.35);
  EXPECT_GT(e.valid_fraction, 0.3);
  EXPECT_GT(g.dense.size(), 10000u);
}

}  // namespace
}  // namespace d2gs
