#include <gtest/gtest.h>

#include <cmath>

#include "d2gs/render/activations.hpp"
#include "d2gs/train/densify.hpp"

namespace d2gs {
namespace {

struct Fixture {
  Gaussians model;
  AdamState adam;
  GradientStats stats;
};

// Rows: 0 small + large gradient (clone), 1 large + large gradient (split), 2 small gradient (keep),
// 3 transparent (prune). Scene extent 10 → size limit 0.1.
Fixture make_fixture() {
  Fixture f;
  f.model.resize(4, 1);
  const float log_small = std::log(0.05f), log_large = std::log(0.5f);
  for (std::size_t i = 0; i < 4; ++i) {
    for (int d = 0; d < 3; ++d) {
      f.model.means[i * 3 + d] = static_cast<float>(i);
      f.model.log_scales[i * 3 + d] = i == 1 ? log_large : log_small;
    }
    f.model.opacity_logits[i] = i == 3 ? inverse_sigmoid(0.001f) : inverse_sigmoid(0.5f);
    f.model.sh_dc[i * 3] = 10.0f + static_cast<float>(i);
  }
  f.adam = Adam::make_state(f.model);
  for (auto& v : f.adam.exp_avg.means) v = 1.0f;
  f.stats.reset(4);
  // Two iterations; Gaussian 2 invisible in the second (counted once), 3 never visible.
  f.stats.add({0.001f, 0.0f, 0.0f, 0.002f, 0.0001f, 0.0f, 0.0f, 0.0f}, {3, 3, 3, 0});
  f.stats.add({0.0f, 0.001f, 0.0f, 0.0f, 0.5f, 0.5f, 0.0f, 0.0f}, {3, 3, 0, 0});
  return f;
}

TEST(GradientStats, MeanOverVisibleIterations) {
  const auto f = make_fixture();
  const auto m = f.stats.mean();
  EXPECT_NEAR(m[0], 0.001f, 1e-9f);
  EXPECT_NEAR(m[1], 0.001f, 1e-9f);   // (0.002 + 0) / 2
  EXPECT_NEAR(m[2], 0.0001f, 1e-9f);  // second iteration not visible: ignored
  EXPECT_EQ(m[3], 0.0f);
}

TEST(Densify, CloneSplitPruneKeepEverythingAligned) {
  auto f = make_fixture();
  Rng rng(42);
  const auto report = densify_and_prune(f.model, f.adam, f.stats, 10.0f, DensifyOptions{}, rng);
  EXPECT_EQ(report.cloned, 1u);
  EXPECT_EQ(report.split, 1u);
  EXPECT_EQ(report.pruned, 1u);
  // Layout: kept originals [0, 2], clone of 0, two children of 1.
  ASSERT_EQ(f.model.size(), 5u);
  EXPECT_EQ(report.source, (std::vector<std::uint32_t>{0, 2, 0, 1, 1}));
  f.model.validate();
  EXPECT_EQ(f.adam.exp_avg.size(), 5u);
  EXPECT_EQ(f.adam.exp_avg_sq.size(), 5u);
  EXPECT_EQ(f.stats.size(), 5u);
  EXPECT_EQ(f.adam.exp_avg.means[0], 1.0f);  // survivors keep their moments
  EXPECT_EQ(f.adam.exp_avg.means[3], 1.0f);
  for (std::size_t r = 2; r < 5; ++r) EXPECT_EQ(f.adam.exp_avg.means[r * 3], 0.0f);  // new rows: zero
  EXPECT_EQ(f.model.sh_dc[2 * 3], 10.0f);  // the clone is an exact copy of row 0
  EXPECT_EQ(f.model.means[2 * 3], 0.0f);
  for (std::size_t r = 3; r < 5; ++r) {
    EXPECT_EQ(f.model.sh_dc[r * 3], 11.0f);
    EXPECT_NEAR(std::exp(f.model.log_scales[r * 3]), 0.5f / 1.6f, 1e-6f);
    EXPECT_NE(f.model.means[r * 3], 1.0f);  // displaced from the parent
  }
  for (float g : f.stats.mean()) EXPECT_EQ(g, 0.0f);  // statistics restart
}

TEST(Densify, SplitOffsetsFollowTheParentShape) {
  // One elongated, rotated parent split many times: offsets ~ N(0, R S² Rᵀ).
  Gaussians model;
  model.resize(1, 0);
  model.log_scales = {std::log(2.0f), std::log(0.1f), std::log(0.1f)};
  const float half = 0.5f * 1.5707963f;  // 90° about z: the long axis becomes world y
  model.quats = {std::cos(half), 0.0f, 0.0f, std::sin(half)};
  model.opacity_logits = {0.0f};
  double sx = 0, sy = 0, syy = 0, sxx = 0;
  const int trials = 4000;
  Rng rng(7);
  for (int t = 0; t < trials; ++t) {
    Gaussians m = model;
    AdamState adam = Adam::make_state(m);
    GradientStats stats;
    stats.reset(1);
    stats.add({1.0f, 0.0f}, {1});
    densify_and_prune(m, adam, stats, 1.0f, DensifyOptions{}, rng);
    for (std::size_t r = 0; r < m.size(); ++r) {
      sx += m.means[r * 3];
      sy += m.means[r * 3 + 1];
      sxx += m.means[r * 3] * m.means[r * 3];
      syy += m.means[r * 3 + 1] * m.means[r * 3 + 1];
    }
  }
  const double count = 2.0 * trials;
  EXPECT_NEAR(sy / count, 0.0, 0.1);
  EXPECT_NEAR(syy / count, 4.0, 0.3);   // variance along the long axis: 2²
  EXPECT_NEAR(sxx / count, 0.01, 0.002);
  EXPECT_NEAR(sx / count, 0.0, 0.01);
}

TEST(Densify, SameSeedSameResult) {
  auto a = make_fixture(), b = make_fixture();
  Rng ra(9), rb(9);
  densify_and_prune(a.model, a.adam, a.stats, 10.0f, DensifyOptions{}, ra);
  densify_and_prune(b.model, b.adam, b.stats, 10.0f, DensifyOptions{}, rb);
  EXPECT_EQ(a.model.means, b.model.means);
}

TEST(Densify, OpacityResetCapsAndZeroesMoments) {
  auto f = make_fixture();
  for (auto& v : f.adam.exp_avg.opacity_logits) v = 3.0f;
  reset_opacity(f.model, f.adam);
  EXPECT_NEAR(sigmoid(f.model.opacity_logits[0]), 0.01f, 1e-6f);
  EXPECT_NEAR(sigmoid(f.model.opacity_logits[3]), 0.001f, 1e-6f);  // below the cap: unchanged
  for (float v : f.adam.exp_avg.opacity_logits) EXPECT_EQ(v, 0.0f);
  EXPECT_EQ(f.adam.exp_avg.means[0], 1.0f);
}

TEST(Densify, MisalignedInputsAreRejected) {
  auto f = make_fixture();
  f.stats.reset(3);
  Rng rng(1);
  EXPECT_ANY_THROW(densify_and_prune(f.model, f.adam, f.stats, 10.0f, DensifyOptions{}, rng));
}

TEST(Rng, StreamsAreReproducibleAndIndependent) {
  Rng a = Rng::stream(5, "dropout"), b = Rng::stream(5, "dropout"), c = Rng::stream(5, "cameras");
  for (int i = 0; i < 100; ++i) EXPECT_EQ(a.next_u64(), b.next_u64());
  EXPECT_NE(Rng::stream(5, "dropout").next_u64(), c.next_u64());
  Rng r(123);
  double s = 0, s2 = 0;
  const int n = 200000;
  for (int i = 0; i < n; ++i) {
    const double x = r.normal();
    s += x;
    s2 += x * x;
  }
  EXPECT_NEAR(s / n, 0.0, 0.01);
  EXPECT_NEAR(s2 / n, 1.0, 0.01);
  int hits = 0;
  for (int i = 0; i < n; ++i) hits += r.bernoulli(0.3);
  EXPECT_NEAR(hits / static_cast<double>(n), 0.3, 0.005);
  for (int i = 0; i < 1000; ++i) EXPECT_LT(r.below(7), 7u);
}

}  // namespace
}  // namespace d2gs
