#include <gtest/gtest.h>

#include <cmath>

#include "d2gs/core/random.hpp"
#include "d2gs/train/losses.hpp"

namespace d2gs {
namespace {

TEST(L1, ValueAndGradient) {
  const std::vector<float> a = {0.5f, 0.2f, 0.9f, 0.4f}, b = {0.1f, 0.2f, 1.0f, 0.0f};
  std::vector<float> g(4, 0.0f);
  EXPECT_NEAR(l1_loss(a.data(), b.data(), 4, g.data(), 0.8f), (0.4 + 0.0 + 0.1 + 0.4) / 4, 1e-7);
  EXPECT_EQ(g, (std::vector<float>{0.2f, 0.0f, -0.2f, 0.2f}));
}

TEST(DafeMask, PercentileSelectsTheFarthestPixels) {
  // 20 pixels with depth 1..20: np.percentile(depth, 90) = 18.1, so the mask holds depths 19 and 20.
  std::vector<float> depth(20);
  for (int i = 0; i < 20; ++i) depth[i] = static_cast<float>(i + 1);
  const auto m = dafe_mask(depth, PriorKind::Depth, DafeMaskRule::Percentile, 10);
  int count = 0;
  for (int i = 0; i < 20; ++i) count += m[i];
  EXPECT_EQ(count, 2);
  EXPECT_TRUE(m[18] && m[19]);
  // The same scene as disparity (1/depth): far = low disparity, same pixels.
  std::vector<float> disparity(20);
  for (int i = 0; i < 20; ++i) disparity[i] = 1.0f / depth[i];
  EXPECT_EQ(dafe_mask(disparity, PriorKind::Disparity, DafeMaskRule::Percentile, 10), m);
}

TEST(DafeMask, PercentileIsInvariantToAffineDisparity) {
  Rng rng(2);
  std::vector<float> disp(5000), changed(5000);
  for (std::size_t i = 0; i < disp.size(); ++i) {
    disp[i] = static_cast<float>(rng.uniform());
    changed[i] = 3.5f * disp[i] + 12.0f;  // unknown scale and shift of a monocular network
  }
  EXPECT_EQ(dafe_mask(disp, PriorKind::Disparity, DafeMaskRule::Percentile, 15),
            dafe_mask(changed, PriorKind::Disparity, DafeMaskRule::Percentile, 15));
}

TEST(DafeMask, ThresholdRuleAndValidity) {
  const std::vector<float> depth = {1, 5, 9, 10, NAN};
  const auto m = dafe_mask(depth, PriorKind::Depth, DafeMaskRule::Threshold, 0.8);  // > 8
  EXPECT_EQ(m, (std::vector<std::uint8_t>{0, 0, 1, 1, 0}));
  const std::vector<std::uint8_t> valid = {1, 1, 1, 0, 1};
  EXPECT_EQ(dafe_mask(depth, PriorKind::Depth, DafeMaskRule::Threshold, 0.8, &valid),
            (std::vector<std::uint8_t>{0, 0, 1, 0, 0}));  // max over valid pixels is 9 → > 7.2
  EXPECT_ANY_THROW(dafe_mask(depth, PriorKind::Disparity, DafeMaskRule::Threshold, 0.5));
}

TEST(DafeLoss, PaperAndReleaseForms) {
  // 2×1 image, 3 channels; only pixel 1 is far.
  const std::vector<float> a = {0.0f, 0.0f, 0.0f, 0.5f, 0.2f, 0.1f};
  const std::vector<float> b = {1.0f, 1.0f, 1.0f, 0.1f, 0.4f, 0.1f};
  const std::vector<std::uint8_t> mask = {0, 1};
  std::vector<float> g(6, 0.0f);
  // Paper: Σ_c |a−b| over the masked pixel / 1 pixel = 0.4 + 0.2 + 0 = 0.6.
  EXPECT_NEAR(dafe_loss(a.data(), b.data(), 2, 1, 3, mask, DafeLossForm::Paper, g.data(), 1.0f), 0.6, 1e-6);
  EXPECT_EQ(g, (std::vector<float>{0, 0, 0, 1.0f, -1.0f, 0}));
  // Release: the same sum over all 6 values.
  std::fill(g.begin(), g.end(), 0.0f);
  EXPECT_NEAR(dafe_loss(a.data(), b.data(), 2, 1, 3, mask, DafeLossForm::Release, g.data(), 1.0f), 0.1, 1e-6);
  EXPECT_NEAR(g[3], 1.0f / 6.0f, 1e-7f);
  EXPECT_EQ(dafe_loss(a.data(), b.data(), 2, 1, 3, {0, 0}, DafeLossForm::Paper), 0.0);
}

}  // namespace
}  // namespace d2gs
