// Synthetic multi-view geometry with known answers: the fundamental matrix of two posed cameras and the
// epipolar filter, track merging, triangulation (exact projections, cheirality, angle and error filters).
#include <gtest/gtest.h>

#include <cmath>

#include <glm/gtc/matrix_transform.hpp>

#include "d2gs/core/error.hpp"
#include "d2gs/geometry/matching.hpp"
#include "d2gs/geometry/tracks.hpp"
#include "d2gs/geometry/triangulation.hpp"

namespace d2gs {
namespace {

// A camera at `centre` looking at `target` (OpenCV axes: y down), 504×378, fern-like focal length.
Camera look_at(const glm::dvec3& centre, const glm::dvec3& target) {
  Camera c;
  c.width = 504;
  c.height = 378;
  c.fx = c.fy = 407.6;
  c.cx = 252.0;
  c.cy = 189.0;
  const glm::dvec3 z = glm::normalize(target - centre);
  const glm::dvec3 x = glm::normalize(glm::cross(glm::dvec3(0, -1, 0), z));  // right
  const glm::dvec3 y = glm::cross(z, x);                                     // down
  glm::dmat3 R_c2w(x, y, z);
  c.R_world_to_cam = glm::transpose(R_c2w);
  c.t_world_to_cam = -c.R_world_to_cam * centre;
  return c;
}

// Pixel of a camera-space point without the cheirality check (for points behind the camera).
glm::dvec2 raw_projection(const Camera& c, const glm::dvec3& X) {
  const glm::dvec3 p = c.R_world_to_cam * X + c.t_world_to_cam;
  return {c.fx * p.x / p.z + c.cx, c.fy * p.y / p.z + c.cy};
}

TEST(Epipolar, ExactCorrespondencesLieOnTheirEpipolarLines) {
  const Camera a = look_at({0, 0, 0}, {0.2, 0.1, 8}), b = look_at({1.0, 0.3, 0.2}, {0, 0, 9});
  const glm::dmat3 F = fundamental_from_cameras(a, b);
  for (const glm::dvec3 X : {glm::dvec3(0, 0, 6), glm::dvec3(-1.5, 0.7, 9), glm::dvec3(2, -1, 14)}) {
    const auto xa = project_point(a, X), xb = project_point(b, X);
    ASSERT_TRUE(xa && xb);
    EXPECT_LT(epipolar_distance(F, *xa, *xb), 1e-8);
    EXPECT_NEAR(glm::dot(glm::dvec3(*xb, 1.0), F * glm::dvec3(*xa, 1.0)), 0.0, 1e-9);
  }
}

TEST(Epipolar, DistanceIsThePixelOffsetFromTheLine) {
  const Camera a = look_at({0, 0, 0}, {0, 0, 8}), b = look_at({1.0, 0, 0}, {1.0, 0, 8});
  // Pure sideways translation with parallel axes: epipolar lines are image rows, so a vertical offset
  // of k pixels is a distance of k pixels, and a horizontal offset none.
  const glm::dmat3 F = fundamental_from_cameras(a, b);
  const glm::dvec3 X(0.3, 0.2, 7);
  const glm::dvec2 xa = *project_point(a, X), xb = *project_point(b, X);
  EXPECT_NEAR(epipolar_distance(F, xa, xb + glm::dvec2(0, 3)), 3.0, 1e-9);
  EXPECT_NEAR(epipolar_distance(F, xa, xb + glm::dvec2(25, 0)), 0.0, 1e-9);

  ViewFeatures fa, fb;
  fa.keypoints = {xa, xa, xa};
  fb.keypoints = {xb, xb + glm::dvec2(0, 1.5), xb + glm::dvec2(0, 2.5)};
  const std::vector<FeatureMatch> m = {{0, 0}, {1, 1}, {2, 2}};
  const auto kept = filter_epipolar(m, fa, fb, a, b, 2.0);
  ASSERT_EQ(kept.size(), 2u);
  EXPECT_EQ(kept[0].b, 0);
  EXPECT_EQ(kept[1].b, 1);
}

TEST(Matching, RatioTestAndMutualCheck) {
  // Descriptors: a0 ≈ b0 (unique), a1 equally close to b1 and b2 (ambiguous: fails the ratio test),
  // a2 and a3 both nearest to b3 (only the mutual one survives).
  ViewFeatures a, b;
  const auto desc = [](float v0, float v1) {
    std::vector<float> d(kSiftDescriptorSize, 0.0f);
    d[0] = v0, d[1] = v1;
    return d;
  };
  const auto add = [](ViewFeatures& f, const std::vector<float>& d) {
    f.keypoints.emplace_back(0.0, 0.0);
    f.descriptors.insert(f.descriptors.end(), d.begin(), d.end());
  };
  add(a, desc(0, 0)), add(a, desc(100, 0)), add(a, desc(0, 101)), add(a, desc(0, 103));
  add(b, desc(0, 1)), add(b, desc(100, 10)), add(b, desc(100, -10)), add(b, desc(0, 100.5));
  const auto m = match_descriptors(a, b, MatchOptions{});
  ASSERT_EQ(m.size(), 2u);
  EXPECT_EQ(m[0].a, 0);
  EXPECT_EQ(m[0].b, 0);
  EXPECT_EQ(m[1].a, 2);
  EXPECT_EQ(m[1].b, 3);
  MatchOptions no_mutual;
  no_mutual.mutual = false;
  EXPECT_EQ(match_descriptors(a, b, no_mutual).size(), 3u);
}

TEST(Matching, GuidedSearchStaysOnTheEpipolarLine) {
  // Two identical descriptors in b: a global ratio test cannot tell them apart; only one of them lies on
  // the epipolar line of a's keypoint, so the guided search matches it.
  const Camera a = look_at({0, 0, 0}, {0, 0, 8}), b = look_at({1.0, 0, 0}, {1.0, 0, 8});
  const glm::dvec3 X(0.3, 0.2, 7);
  ViewFeatures fa, fb;
  std::vector<float> d(kSiftDescriptorSize, 1.0f);
  fa.keypoints = {*project_point(a, X)};
  fa.descriptors = d;
  fb.keypoints = {*project_point(b, X) + glm::dvec2(0, 40), *project_point(b, X) + glm::dvec2(-3, 0.5)};
  fb.descriptors = d;
  fb.descriptors.insert(fb.descriptors.end(), d.begin(), d.end());
  EXPECT_TRUE(match_descriptors(fa, fb, MatchOptions{}).empty());
  const auto m = match_guided(fa, fb, a, b, MatchOptions{}, 2.0);
  ASSERT_EQ(m.size(), 1u);
  EXPECT_EQ(m[0].b, 1);
}

TEST(Tracks, MatchesChainAcrossViews) {
  const std::vector<std::size_t> counts = {10, 10, 10};
  const std::vector<PairMatches> pairs = {{1, 2, {{7, 3}}}, {0, 1, {{5, 7}, {2, 2}}}};
  TrackStats st;
  const auto tracks = build_tracks(counts, pairs, &st);
  ASSERT_EQ(tracks.size(), 2u);
  // Ordered by smallest node: (0,2) first, then (0,5).
  ASSERT_EQ(tracks[0].size(), 2u);
  EXPECT_EQ(tracks[0][0].feature, 2);
  ASSERT_EQ(tracks[1].size(), 3u);
  EXPECT_EQ(tracks[1][0].view, 0);
  EXPECT_EQ(tracks[1][0].feature, 5);
  EXPECT_EQ(tracks[1][1].view, 1);
  EXPECT_EQ(tracks[1][1].feature, 7);
  EXPECT_EQ(tracks[1][2].view, 2);
  EXPECT_EQ(tracks[1][2].feature, 3);
  EXPECT_EQ(st.inconsistent, 0u);
  // The same matches in another pair order give the same tracks.
  const auto again = build_tracks(counts, {pairs[1], pairs[0]});
  ASSERT_EQ(again.size(), tracks.size());
  for (std::size_t t = 0; t < tracks.size(); ++t)
    for (std::size_t k = 0; k < tracks[t].size(); ++k) {
      EXPECT_EQ(again[t][k].view, tracks[t][k].view);
      EXPECT_EQ(again[t][k].feature, tracks[t][k].feature);
    }
}

TEST(Tracks, ComponentWithTwoKeypointsOfOneViewIsDropped) {
  // 0:5 – 1:7 – 2:3 – 0:6: view 0 appears twice, so one of the matches is wrong.
  const std::vector<PairMatches> pairs = {{0, 1, {{5, 7}, {1, 1}}}, {1, 2, {{7, 3}}}, {0, 2, {{6, 3}}}};
  TrackStats st;
  const auto tracks = build_tracks({10, 10, 10}, pairs, &st);
  ASSERT_EQ(tracks.size(), 1u);
  EXPECT_EQ(tracks[0][0].feature, 1);
  EXPECT_EQ(st.inconsistent, 1u);
  EXPECT_THROW(build_tracks({10, 10}, {{0, 1, {{10, 0}}}}), Error);
}

std::vector<Observation> observe(const std::vector<const Camera*>& cams, const glm::dvec3& X) {
  std::vector<Observation> obs;
  for (const auto* c : cams) obs.push_back({c, raw_projection(*c, X)});
  return obs;
}

TEST(Triangulation, ExactProjectionsGiveThePointBack) {
  const Camera a = look_at({0, 0, 0}, {0, 0, 9}), b = look_at({0.6, 0.1, 0}, {0, 0, 9}),
               c = look_at({-0.5, 0.4, 0.1}, {0, 0, 9});
  for (const glm::dvec3 X : {glm::dvec3(0.5, -0.3, 4), glm::dvec3(-2, 1, 12), glm::dvec3(3, 2, 30)}) {
    for (const auto& cams : {std::vector<const Camera*>{&a, &b}, std::vector<const Camera*>{&a, &b, &c}}) {
      const auto obs = observe(cams, X);
      const auto dlt = triangulate_dlt(obs);
      ASSERT_TRUE(dlt);
      EXPECT_LT(glm::length(*dlt - X), 1e-7 * glm::length(X));
      const auto t = triangulate(obs, TriangulationOptions{});
      EXPECT_EQ(t.result, TriangulationResult::Ok);
      EXPECT_LT(glm::length(t.position - X), 1e-7 * glm::length(X));
      EXPECT_LT(t.mean_error_px, 1e-6);
      EXPECT_GT(t.angle_deg, 1.0);
    }
  }
}

TEST(Triangulation, RefinementReducesTheErrorOfNoisyObservations) {
  const Camera a = look_at({0, 0, 0}, {0, 0, 9}), b = look_at({0.8, 0, 0}, {0, 0, 9}), c = look_at({0, 0.6, 0}, {0, 0, 9});
  const glm::dvec3 X(0.4, 0.2, 6);
  auto obs = observe({&a, &b, &c}, X);
  obs[0].pixel += glm::dvec2(0.7, -0.4);
  obs[1].pixel += glm::dvec2(-0.5, 0.6);
  obs[2].pixel += glm::dvec2(0.3, 0.5);
  const glm::dvec3 dlt = *triangulate_dlt(obs);
  const glm::dvec3 refined = refine_point(obs, dlt);
  const auto sq = [&](const glm::dvec3& p) {
    double s = 0;
    for (const auto& o : obs) {
      const glm::dvec2 d = *project_point(*o.camera, p) - o.pixel;
      s += glm::dot(d, d);
    }
    return s;
  };
  EXPECT_LE(sq(refined), sq(dlt) + 1e-12);
  EXPECT_LT(glm::length(refined - X), 0.1);
}

TEST(Triangulation, CheiralityRejectsPointsBehindACamera) {
  const Camera a = look_at({0, 0, 0}, {0, 0, 9}), b = look_at({0.6, 0, 0}, {0.6, 0, 9});
  // Behind both cameras: its (mirrored) projections are consistent, the DLT finds it, the filter refuses.
  const glm::dvec3 X(0.2, 0.1, -5);
  const auto t = triangulate(observe({&a, &b}, X), TriangulationOptions{});
  EXPECT_EQ(t.result, TriangulationResult::BehindCamera);
  EXPECT_FALSE(project_point(a, X));
}

TEST(Triangulation, SmallAngleAndLargeErrorAreRejected) {
  const Camera a = look_at({0, 0, 0}, {0, 0, 9}), near_a = look_at({0.01, 0, 0}, {0.01, 0, 9}),
               b = look_at({0.8, 0, 0}, {0.8, 0, 9});
  const glm::dvec3 X(0.3, 0.2, 8);
  const auto small = triangulate(observe({&a, &near_a}, X), TriangulationOptions{});
  EXPECT_EQ(small.result, TriangulationResult::SmallAngle);
  EXPECT_LT(small.angle_deg, 0.1);
  auto obs = observe({&a, &b}, X);
  obs[1].pixel.y += 12.0;  // off the epipolar line: no point explains both observations
  const auto bad = triangulate(obs, TriangulationOptions{});
  EXPECT_EQ(bad.result, TriangulationResult::ReprojectionError);
  EXPECT_GT(bad.mean_error_px, 2.0);
}

}  // namespace
}  // namespace d2gs
