#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>

#include "d2gs/train/dropout.hpp"

namespace d2gs {
namespace {

TEST(DropGaussian, RateScheduleAndCompensation) {
  EXPECT_DOUBLE_EQ(dropgaussian_rate(0, 10000), 0.0);
  EXPECT_DOUBLE_EQ(dropgaussian_rate(5000, 10000), 0.1);
  EXPECT_DOUBLE_EQ(dropgaussian_rate(10000, 10000), 0.2);
  Rng rng(3);
  std::vector<float> m;
  const std::size_t n = 100000;
  dropgaussian_mask(n, 0.2, rng, m);
  std::size_t dropped = 0;
  for (float v : m) {
    if (v == 0.0f) ++dropped;
    else EXPECT_FLOAT_EQ(v, 1.25f);  // 1 / (1 − 0.2)
  }
  // Binomial(n, 0.2): sd = sqrt(n·0.16) ≈ 126.
  EXPECT_NEAR(static_cast<double>(dropped), 0.2 * n, 5 * 126.0);
}

TEST(DdDrop, LayersMatchTheSortedRanksOnShuffledInputWithTies) {
  // Thresholds are the values at ranks ⌊0.33·N⌋ and ⌊0.67·N⌋ of the sorted depths, for any input order.
  for (std::size_t n : {1u, 2u, 3u, 10u, 1000u, 40001u}) {
    std::mt19937 rng(static_cast<unsigned>(n));
    std::uniform_int_distribution<int> pick(0, 50);  // many ties
    std::vector<float> depth(n);
    for (auto& d : depth) d = 0.1f * static_cast<float>(pick(rng));
    std::vector<float> sorted = depth;
    std::sort(sorted.begin(), sorted.end());
    const float t1 = sorted[std::min(n - 1, static_cast<std::size_t>(0.33 * static_cast<double>(n)))];
    const float t2 = sorted[std::min(n - 1, static_cast<std::size_t>(0.67 * static_cast<double>(n)))];
    const auto layers = depth_layers(depth);
    ASSERT_EQ(layers.size(), n);
    for (std::size_t i = 0; i < n; ++i)
      ASSERT_EQ(layers[i], depth[i] < t1 ? 0 : depth[i] < t2 ? 1 : 2) << "n = " << n << ", i = " << i;
  }
}

TEST(DdDrop, ScoresLayersAndProbabilitiesOnAHandComputedCase) {
  // Depths 1..9 (N = 9): t1 = s[2] = 3, t2 = s[6] = 7 → layers near {1,2}, middle {3..6}, far {7,8,9}.
  const std::vector<float> depth = {1, 2, 3, 4, 5, 6, 7, 8, 9};
  const auto layers = depth_layers(depth);
  EXPECT_EQ(layers, (std::vector<std::uint8_t>{0, 0, 1, 1, 1, 1, 2, 2, 2}));
  // Density ρ = −mean kNN distance: here −(1..9) reversed so the nearest is the densest.
  std::vector<float> density = {-1, -2, -3, -4, -5, -6, -7, -8, -9};
  DdDropOptions o;  // paper: w_d = w_ρ = 0.5, r 0.05 → 0.3 over 10 000
  EXPECT_DOUBLE_EQ(dd_drop_rate(o, 0), 0.05);
  EXPECT_DOUBLE_EQ(dd_drop_rate(o, 5000), 0.175);
  EXPECT_DOUBLE_EQ(dd_drop_rate(o, 20000), 0.3);
  const auto p = dd_drop_probabilities(depth, minmax(density), o, 10000);
  // Gaussian 0: depth score 1, density score 1 → S = 1, λ = 1, r = 0.3.
  EXPECT_NEAR(p[0], 0.3, 1e-7);
  // Gaussian 4 (depth 5): depth score 0.5, density score 0.5 → S = 0.5, λ = 0.7.
  EXPECT_NEAR(p[4], 0.5 * 0.7 * 0.3, 1e-7);
  // Gaussian 8: S = 0 → never dropped.
  EXPECT_EQ(p[8], 0.0f);
  // Ablations: without layers λ = 1; without density only the depth term remains.
  o.use_layers = false;
  o.use_density_score = false;
  const auto q = dd_drop_probabilities(depth, minmax(density), o, 10000);
  EXPECT_NEAR(q[4], 0.5 * 0.5 * 0.3, 1e-7);
}

TEST(DdDrop, EmpiricalDropCountMatchesSumOfProbabilities) {
  Rng init(5);
  const std::size_t n = 20000;
  std::vector<float> depth(n), density(n);
  for (std::size_t i = 0; i < n; ++i) {
    depth[i] = static_cast<float>(1.0 + 50.0 * init.uniform());
    density[i] = static_cast<float>(-init.uniform());
  }
  const auto p = dd_drop_probabilities(depth, minmax(density), DdDropOptions{}, 7000);
  const double expected = std::accumulate(p.begin(), p.end(), 0.0);
  double variance = 0;
  for (float v : p) variance += v * (1.0 - v);
  Rng rng(11);
  std::vector<float> m;
  double total = 0;
  const int draws = 50;
  for (int d = 0; d < draws; ++d) {
    bernoulli_mask(p, rng, m);
    for (float v : m) total += v == 0.0f;
  }
  // Mean over 50 draws: sd = sqrt(Σp(1−p) / 50).
  EXPECT_NEAR(total / draws, expected, 5 * std::sqrt(variance / draws));
}

TEST(DdDrop, CompensatedMaskKeepsTheExpectedOpacity) {
  // Kept Gaussians get exactly 1/(1 − p_i); p = 1 always drops; E[multiplier] = 1 for every Gaussian.
  const std::vector<float> p = {0.0f, 0.25f, 0.5f, 0.9f, 1.0f};
  Rng rng(3);
  std::vector<float> m;
  std::vector<double> sum(p.size(), 0.0);
  const int draws = 40000;
  for (int d = 0; d < draws; ++d) {
    bernoulli_mask(p, rng, m, /*compensate=*/true);
    for (std::size_t i = 0; i < p.size(); ++i) {
      if (m[i] != 0.0f) {
        EXPECT_FLOAT_EQ(m[i], 1.0f / (1.0f - p[i])) << i;
      }
      sum[i] += m[i];
    }
  }
  EXPECT_EQ(sum[4], 0.0);
  EXPECT_EQ(sum[0], draws);
  for (std::size_t i = 1; i < 4; ++i) {
    // sd of the mean: sqrt(p / (1 − p) / draws).
    const double sd = std::sqrt(p[i] / (1.0 - p[i]) / draws);
    EXPECT_NEAR(sum[i] / draws, 1.0, 5 * sd) << i;
  }
  // Without compensation the same draws give 0/1 with the same zeros.
  Rng a(9), b(9);
  std::vector<float> plain, comp;
  bernoulli_mask(p, a, plain);
  bernoulli_mask(p, b, comp, true);
  for (std::size_t i = 0; i < p.size(); ++i) EXPECT_EQ(plain[i] == 0.0f, comp[i] == 0.0f);
}

TEST(DdDrop, DepthFormulas) {
  Gaussians g;
  g.resize(1, 0);
  g.means = {1.0f, 2.0f, 5.0f};
  Camera cam;
  // Camera at (0, 0, -1) looking along +z: R = I, t = (0, 0, 1).
  cam.t_world_to_cam = {0.0, 0.0, 1.0};
  EXPECT_NEAR(gaussian_depths(g, cam, DepthMode::Euclidean)[0], std::sqrt(1.0 + 4.0 + 36.0), 1e-5);
  EXPECT_NEAR(gaussian_depths(g, cam, DepthMode::ReleaseDot)[0], 5.0, 1e-6);  // no translation
  // A rotation about y by 90°: third column of R_w2c is (sin, 0, cos) = (1, 0, 0) in glm's column form.
  cam.R_world_to_cam = glm::dmat3(glm::dvec3(0, 0, -1), glm::dvec3(0, 1, 0), glm::dvec3(1, 0, 0));
  EXPECT_NEAR(gaussian_depths(g, cam, DepthMode::ReleaseDot)[0], 1.0, 1e-6);
}

TEST(DdDrop, DensityScoreIsHighestInTheDenseCluster) {
  Gaussians g;
  g.resize(10, 0);
  // Seven points packed within 0.01 and three spread 1 apart.
  for (int i = 0; i < 7; ++i) g.means[static_cast<std::size_t>(i) * 3] = 0.01f * static_cast<float>(i) / 7.0f;
  for (int i = 7; i < 10; ++i) g.means[static_cast<std::size_t>(i) * 3] = static_cast<float>(i - 5);
  const auto s = density_scores(g);
  for (int i = 0; i < 7; ++i) EXPECT_GT(s[i], 0.9f);
  EXPECT_EQ(*std::min_element(s.begin(), s.end()), 0.0f);
  EXPECT_LT(s[9], 0.1f);
}

TEST(DdDrop, MinmaxOfConstantIsZero) {
  EXPECT_EQ(minmax({2.0f, 2.0f}), (std::vector<float>{0.0f, 0.0f}));
  EXPECT_EQ(minmax({1.0f, 3.0f, 2.0f}), (std::vector<float>{0.0f, 1.0f, 0.5f}));
}

}  // namespace
}  // namespace d2gs
