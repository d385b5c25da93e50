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

// The stereo-depth loss: its value by hand, which pixels count, and its gradient by central differences
// in depth and alpha (away from the kink of |x|).
TEST(DisparityL1, ValueWhichPixelsCountAndGradient) {
  // Pixel 0: u = 0.8 / 2 = 0.4 against v = 1 / 2 = 0.5; pixel 1: u = 1 / 1 = 1 against v = 1 / 1.25 = 0.8;
  // pixel 2: no target; pixel 3: alpha below the cut (it still counts in the normaliser); pixel 4: D = 0.
  const std::vector<float> d = {2.0f, 1.0f, 3.0f, 1.0f, 0.0f}, a = {0.8f, 1.0f, 0.9f, 0.3f, 0.7f},
                           z = {2.0f, 1.25f, 0.0f, 4.0f, 1.0f};
  std::vector<float> gd(5, 0.0f), ga(5, 0.0f);
  const double norm = 1.0 / (0.5 + 0.8 + 0.25 + 1.0);
  EXPECT_NEAR(disparity_l1_loss(d.data(), a.data(), z.data(), 5, 0.5, gd.data(), ga.data(), 2.0f), (0.1 + 0.2) * norm,
              1e-7);
  EXPECT_NEAR(gd[0], 2.0 * norm * -1.0 * (-0.8 / 4.0), 1e-7);
  EXPECT_NEAR(ga[0], 2.0 * norm * -1.0 / 2.0, 1e-7);
  EXPECT_NEAR(gd[1], 2.0 * norm * 1.0 * (-1.0 / 1.0), 1e-7);
  EXPECT_NEAR(ga[1], 2.0 * norm * 1.0 / 1.0, 1e-7);
  for (int i : {2, 3, 4}) {
    EXPECT_EQ(gd[static_cast<std::size_t>(i)], 0.0f) << i;
    EXPECT_EQ(ga[static_cast<std::size_t>(i)], 0.0f) << i;
  }
  // No target anywhere: 0 and no gradient.
  const std::vector<float> none(5, 0.0f);
  EXPECT_EQ(disparity_l1_loss(d.data(), a.data(), none.data(), 5, 0.5, gd.data(), ga.data()), 0.0);

  // Central differences on random pixels.
  Rng rng(7);
  const std::size_t n = 64;
  std::vector<float> ds(n), as(n), zs(n);
  for (std::size_t i = 0; i < n; ++i) {
    ds[i] = static_cast<float>(1.0 + 2.0 * rng.uniform());
    as[i] = static_cast<float>(0.6 + 0.4 * rng.uniform());
    zs[i] = i % 5 == 0 ? 0.0f : static_cast<float>(0.5 + 2.0 * rng.uniform());
  }
  std::vector<float> g_d(n, 0.0f), g_a(n, 0.0f);
  disparity_l1_loss(ds.data(), as.data(), zs.data(), n, 0.5, g_d.data(), g_a.data(), 1.0f);
  const float h = 1e-3f;
  int checked = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (zs[i] == 0.0f) continue;
    if (std::abs(as[i] / ds[i] - 1.0f / zs[i]) < 0.02f) continue;  // too near the kink for h
    for (const bool in_depth : {true, false}) {
      auto pd = ds, md = ds, pa = as, ma = as;
      (in_depth ? pd : pa)[i] += h;
      (in_depth ? md : ma)[i] -= h;
      const double step = in_depth ? static_cast<double>(pd[i]) - md[i] : static_cast<double>(pa[i]) - ma[i];
      const double numeric = (disparity_l1_loss(pd.data(), pa.data(), zs.data(), n, 0.5) -
                              disparity_l1_loss(md.data(), ma.data(), zs.data(), n, 0.5)) /
                             step;
      const float analytic = in_depth ? g_d[i] : g_a[i];
      EXPECT_NEAR(analytic, numeric, 2e-3 * std::abs(numeric) + 1e-6) << "pixel " << i << (in_depth ? " depth" : " alpha");
      ++checked;
    }
  }
  EXPECT_GT(checked, 60);
}

}  // namespace
}  // namespace d2gs
