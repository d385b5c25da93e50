// Model → Gaussian mixture (method.md §7 steps 1-2): activations, covariances, depth strata, eigen clamp.
#include <cmath>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include "d2gs/core/error.hpp"
#include "d2gs/eval/gaussian_mixture.hpp"

namespace d2gs {
namespace {

void expect_mat_near(const glm::dmat3& a, const glm::dmat3& b, double tol) {
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) EXPECT_NEAR(a[c][r], b[c][r], tol) << "entry row " << r << " col " << c;
}

glm::dmat3 rotation_z(double angle) {
  return quaternion_to_rotation(std::cos(angle / 2), 0, 0, std::sin(angle / 2));
}

TEST(Mixture, QuaternionToRotation) {
  expect_mat_near(quaternion_to_rotation(1, 0, 0, 0), glm::dmat3(1.0), 0);
  expect_mat_near(quaternion_to_rotation(0, 0, 0, 0), glm::dmat3(1.0), 0);  // zero quaternion: identity
  // 90° about z maps x to y: column 0 of R is (0, 1, 0).
  const glm::dmat3 r = rotation_z(std::acos(-1.0) / 2);
  EXPECT_NEAR(r[0][0], 0.0, 1e-15);
  EXPECT_NEAR(r[0][1], 1.0, 1e-15);
  EXPECT_NEAR(r[1][0], -1.0, 1e-15);
  // Normalised at use: a scaled quaternion gives the same rotation.
  expect_mat_near(quaternion_to_rotation(2, 4, -6, 8), quaternion_to_rotation(0.1, 0.2, -0.3, 0.4), 1e-15);
  const glm::dmat3 q = quaternion_to_rotation(0.3, -1.2, 0.7, 2.0);
  expect_mat_near(glm::transpose(q) * q, glm::dmat3(1.0), 1e-14);
  EXPECT_NEAR(glm::determinant(q), 1.0, 1e-14);
}

TEST(Mixture, CovarianceAndWeightsHandComputed) {
  Gaussians model;
  model.resize(2, 0);
  // Gaussian 0: scales (1, 2, 3), rotation 90° about z → Σ = R diag(1, 4, 9) Rᵀ = diag(4, 1, 9).
  model.log_scales = {0.0f, std::log(2.0f), std::log(3.0f), 0.0f, 0.0f, 0.0f};
  const float s = static_cast<float>(std::sqrt(0.5));
  model.quats = {s, 0, 0, s, 1, 0, 0, 0};
  model.opacity_logits = {0.0f, std::log(3.0f)};  // α = 0.5, 0.75 → weights 0.4, 0.6
  model.means = {1, 2, 3, 4, 5, 6};
  const GaussianMixture mix = mixture_from_model(model);
  ASSERT_EQ(mix.size(), 2u);
  expect_mat_near(mix.covariances[0], glm::dmat3(glm::dvec3(4, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 9)), 2e-6);
  expect_mat_near(mix.covariances[1], glm::dmat3(1.0), 0);
  EXPECT_NEAR(mix.weights[0], 0.4, 1e-7);
  EXPECT_NEAR(mix.weights[1], 0.6, 1e-7);
  EXPECT_EQ(mix.means[1], glm::dvec3(4, 5, 6));
}

TEST(Mixture, ImrDepthUsesThirdColumnOfWorldToCamera) {
  Gaussians model;
  model.resize(2, 0);
  model.means = {-2, 5, 7, 3, -1, 0.5f};
  Camera cam;
  cam.R_world_to_cam = quaternion_to_rotation(0.8, 0.3, -0.4, 0.2);
  const glm::dmat3& r = cam.R_world_to_cam;
  const glm::dvec3 column2(r[2][0], r[2][1], r[2][2]);  // glm: r[col][row]
  const glm::dvec3 row2(r[0][2], r[1][2], r[2][2]);
  const auto d = imr_depths(model, cam);
  for (int i = 0; i < 2; ++i) {
    const glm::dvec3 x(model.means[3 * i], model.means[3 * i + 1], model.means[3 * i + 2]);
    EXPECT_DOUBLE_EQ(d[static_cast<std::size_t>(i)], std::abs(glm::dot(x, column2)) + 1e-6);
    EXPECT_GT(std::abs(std::abs(glm::dot(x, column2)) - std::abs(glm::dot(x, row2))), 0.1);  // they differ
  }
}

TEST(Mixture, DepthStrataHandComputed) {
  // N = 20, samples = 5: n = 5, b = 4; thirds at N/3 = 6 and 2N/3 = 13.
  // near ranks 0..5 stride 6 → {0}; middle 6..12 stride 4 → {6, 10}; far 13..19 stride 2 → {13, 15, 17, 19}.
  // Depth of model index i is (i * 7) % 20, so rank r belongs to index (3 r) % 20 (7·3 = 21 ≡ 1).
  std::vector<double> depths(20);
  for (int i = 0; i < 20; ++i) depths[static_cast<std::size_t>(i)] = (i * 7) % 20;
  const auto picked = depth_strata_indices(depths, 5);
  const std::vector<std::size_t> ranks = {0, 6, 10, 13, 15, 17, 19};
  ASSERT_EQ(picked.size(), ranks.size());
  for (std::size_t k = 0; k < ranks.size(); ++k) EXPECT_EQ(picked[k], (3 * ranks[k]) % 20) << k;

  // samples ≥ N (N = 10): n = 10, b = 1; thirds at 3 and 6: near stride 3 → {0}, middle stride 1 → {3, 4, 5},
  // far stride max(1, -1) = 1 → {6, 7, 8, 9}.
  std::vector<double> sorted(10);
  std::iota(sorted.begin(), sorted.end(), 0.0);
  EXPECT_EQ(depth_strata_indices(sorted, 10000), (std::vector<std::size_t>{0, 3, 4, 5, 6, 7, 8, 9}));
  // N = 30 000, samples = 10 000: b = 3 → 10 000/5 + ceil(10 000/3) + 10 000 = 15 334.
  std::vector<double> many(30000);
  std::iota(many.begin(), many.end(), 0.0);
  EXPECT_EQ(depth_strata_indices(many, 10000).size(), 2000u + 3334u + 10000u);
  EXPECT_TRUE(depth_strata_indices({}, 10).empty());
  // A phase k starts each third at its first rank + k mod its stride: phase 1 takes near {1}, middle {7, 11},
  // far {14, 16, 18}; phase 5 the near third's rank 5 and the others' phase 1 again (5 mod 4 = 5 mod 2 = 1);
  // phase 6: near 6 mod 6 = 0 → {0}, middle 6 + 2 → {8, 12}, far 13 + 0 → {13, 15, 17, 19}.
  const std::vector<std::vector<std::size_t>> phased = {
      {1, 7, 11, 14, 16, 18}, {5, 7, 11, 14, 16, 18}, {0, 8, 12, 13, 15, 17, 19}};
  const std::size_t phases[3] = {1, 5, 6};
  for (int p = 0; p < 3; ++p) {
    const auto got = depth_strata_indices(depths, 5, phases[p]);
    ASSERT_EQ(got.size(), phased[p].size()) << phases[p];
    for (std::size_t k = 0; k < got.size(); ++k) EXPECT_EQ(got[k], (3 * phased[p][k]) % 20) << phases[p] << " " << k;
  }
  EXPECT_EQ(depth_strata_indices(depths, 5, 0), picked);  // phase 0 is the release's
  // Ties keep model order (stable sort).
  EXPECT_EQ(depth_strata_indices(std::vector<double>(4, 1.0), 4), (std::vector<std::size_t>{0, 1, 2, 3}));
}

TEST(Mixture, EigenClampHandComputed) {
  // Σ_0 = R diag(4, 1, 1e-9) Rᵀ, Σ_1 = I. Largest diagonal entry over both: Σ_0's largest diagonal value.
  const glm::dmat3 r = quaternion_to_rotation(0.9, 0.1, -0.3, 0.2);
  const glm::dmat3 d(glm::dvec3(4, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, 1e-9));
  std::vector<glm::dmat3> covs = {r * d * glm::transpose(r), glm::dmat3(1.0)};
  const double max_diag = std::max({covs[0][0][0], covs[0][1][1], covs[0][2][2]});
  const double floor = covariance_eigenvalue_floor(covs);
  EXPECT_DOUBLE_EQ(floor, (1e-3 * std::sqrt(max_diag)) * (1e-3 * std::sqrt(max_diag)));
  EXPECT_GT(floor, 1e-9);
  EXPECT_EQ(sanitize_covariances(covs, floor), 1u);
  const glm::dmat3 d_clamped(glm::dvec3(4, 0, 0), glm::dvec3(0, 1, 0), glm::dvec3(0, 0, floor));
  expect_mat_near(covs[0], r * d_clamped * glm::transpose(r), 1e-14);
  const SymmetricEigen3 eig = symmetric_eigen(covs[0]);
  EXPECT_NEAR(eig.values[0], floor, 1e-14);
  EXPECT_NEAR(eig.values[1], 1.0, 1e-14);
  EXPECT_NEAR(eig.values[2], 4.0, 1e-14);
  expect_mat_near(covs[1], glm::dmat3(1.0), 0);  // unclamped: only symmetrised
  // Asymmetric input is symmetrised.
  std::vector<glm::dmat3> skew = {glm::dmat3(glm::dvec3(2, 1, 0), glm::dvec3(0, 2, 0), glm::dvec3(0, 0, 2))};
  sanitize_covariances(skew, 0.0);
  EXPECT_DOUBLE_EQ(skew[0][0][1], 0.5);
  EXPECT_DOUBLE_EQ(skew[0][1][0], 0.5);
}

TEST(Mixture, EigenSolversAgreeOnRandomMatrices) {
  std::mt19937_64 rng(7);
  std::normal_distribution<double> n01;
  for (int t = 0; t < 500; ++t) {
    glm::dmat3 a;
    for (int c = 0; c < 3; ++c)
      for (int r = 0; r < 3; ++r) a[c][r] = n01(rng);
    glm::dmat3 m = a * glm::transpose(a);
    if (t % 5 == 0) m[0][1] = m[1][0] = 0.0;  // partly diagonal
    if (t % 7 == 0) m = glm::dmat3(2.0);      // degenerate
    const SymmetricEigen3 eig = symmetric_eigen(m);
    glm::dmat3 scaled = eig.vectors;
    for (int k = 0; k < 3; ++k) scaled[k] *= eig.values[k];
    expect_mat_near(scaled * glm::transpose(eig.vectors), m, 1e-12 * (1 + eig.values[2]));
    expect_mat_near(glm::transpose(eig.vectors) * eig.vectors, glm::dmat3(1.0), 1e-13);
    EXPECT_LE(eig.values[0], eig.values[1]);
    EXPECT_LE(eig.values[1], eig.values[2]);
    const glm::dvec3 closed = symmetric_eigenvalues(m);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(closed[k], eig.values[k], 1e-12 * (1 + eig.values[2])) << t;
  }
}

TEST(Mixture, SubsampledMixtureIsNormalisedAndSanitised) {
  Gaussians model;
  model.resize(100, 0);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1, 1);
  for (auto& v : model.means) v = u(rng);
  for (auto& v : model.log_scales) v = u(rng) * 3 - 4;
  for (auto& v : model.quats) v = u(rng);
  for (auto& v : model.opacity_logits) v = u(rng) * 4;
  model.log_scales[2] = -30;  // one flat Gaussian
  Camera cam;
  MixtureOptions options;
  options.samples = 30;  // b = 3, thirds at 33 and 66: ceil(33/5) + 33/3 + 34 = 7 + 11 + 34
  const GaussianMixture mix = mixture_from_model(model, cam, options);
  EXPECT_EQ(mix.size(), 52u);
  EXPECT_NEAR(std::accumulate(mix.weights.begin(), mix.weights.end(), 0.0), 1.0, 1e-15);
  const double floor = covariance_eigenvalue_floor(mix.covariances);
  for (const auto& c : mix.covariances) EXPECT_GE(symmetric_eigen(c).values[0], floor * (1 - 1e-9));
  options.samples = 0;
  EXPECT_EQ(mixture_from_model(model, cam, options).size(), 100u);
  EXPECT_THROW(mixture_from_model(Gaussians{}, cam, options), Error);
}

}  // namespace
}  // namespace d2gs
