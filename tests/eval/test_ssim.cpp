#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <utility>

#include "d2gs/core/npy.hpp"
#include "d2gs/eval/ssim.hpp"
#include "test_paths.hpp"

namespace d2gs {
namespace {

std::vector<float> to_float(const NpyArray& a) { return {a.values.begin(), a.values.end()}; }

TEST(Ssim, MatchesIndependentNumpyReference) {
  const auto dir = test::source_dir() / "tests/train/fixtures";
  const auto a = read_npy(dir / "ssim_a.npy");
  const auto b = read_npy(dir / "ssim_b.npy");
  const auto expected = read_npy(dir / "ssim_value.npy");
  ASSERT_EQ(a.shape.size(), 3u);
  const int h = static_cast<int>(a.shape[0]), w = static_cast<int>(a.shape[1]);
  const auto fa = to_float(a), fb = to_float(b);
  EXPECT_NEAR(ssim(fa.data(), fb.data(), w, h, 3), expected.values[0], 1e-12);
  EXPECT_NEAR(ssim(fa.data(), fa.data(), w, h, 3), expected.values[1], 1e-12);
  // The float path agrees to float precision.
  Ssim<float> s;
  EXPECT_NEAR(s.evaluate(fa.data(), fb.data(), w, h, 3), expected.values[0], 2e-5);
}

TEST(Ssim, GradientMatchesCentralDifferencesInDouble) {
  const int w = 19, h = 14, c = 3;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::vector<double> a(static_cast<std::size_t>(w) * h * c), b(a.size());
  for (auto& v : a) v = u(rng);
  for (std::size_t i = 0; i < b.size(); ++i) b[i] = 0.7 * a[i] + 0.3 * u(rng);
  Ssim<double> s;
  std::vector<double> grad(a.size());
  s.evaluate(a.data(), b.data(), w, h, c, grad.data(), -0.2);  // d/da of -0.2*SSIM
  const double eps = 1e-6;
  double max_rel = 0;
  for (std::size_t i = 0; i < a.size(); i += 7) {
    const double keep = a[i];
    a[i] = keep + eps;
    const double up = -0.2 * s.evaluate(a.data(), b.data(), w, h, c);
    a[i] = keep - eps;
    const double down = -0.2 * s.evaluate(a.data(), b.data(), w, h, c);
    a[i] = keep;
    const double numeric = (up - down) / (2 * eps);
    max_rel = std::max(max_rel, std::abs(numeric - grad[i]) / std::max(1e-8, std::abs(numeric)));
    EXPECT_NEAR(grad[i], numeric, 1e-9 + 1e-6 * std::abs(numeric)) << "pixel value " << i;
  }
  RecordProperty("max_relative_error", std::to_string(max_rel));
}

TEST(Ssim, FloatGradientAgreesWithDouble) {
  const int w = 64, h = 48, c = 3;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<float> a(static_cast<std::size_t>(w) * h * c), b(a.size()), ga(a.size());
  for (auto& v : a) v = u(rng);
  for (auto& v : b) v = u(rng);
  std::vector<double> da(a.begin(), a.end()), db(b.begin(), b.end()), gd(a.size());
  Ssim<float> sf;
  Ssim<double> sd;
  const float vf = sf.evaluate(a.data(), b.data(), w, h, c, ga.data());
  const double vd = sd.evaluate(da.data(), db.data(), w, h, c, gd.data());
  EXPECT_NEAR(vf, vd, 1e-5);
  double max_abs = 0;
  for (double g : gd) max_abs = std::max(max_abs, std::abs(g));
  for (std::size_t i = 0; i < ga.size(); ++i) EXPECT_NEAR(ga[i], gd[i], 1e-3 * max_abs);
}

// A precomputed reference of the second image gives the value and gradient of evaluate(a, b) bit for bit,
// also on images narrower and lower than the window.
TEST(Ssim, ReferenceIsBitIdentical) {
  for (const auto& [w, h] : {std::pair{64, 48}, std::pair{7, 5}, std::pair{12, 11}, std::pair{1, 30}}) {
    const int c = 3;
    std::mt19937 rng(static_cast<unsigned>(w * 100 + h));
    std::uniform_real_distribution<float> u(0.0f, 1.0f);
    std::vector<float> a(static_cast<std::size_t>(w) * h * c), b(a.size()), g1(a.size()), g2(a.size());
    for (auto& v : a) v = u(rng);
    for (auto& v : b) v = u(rng);
    Ssim<float> s1, s2;
    const float v1 = s1.evaluate(a.data(), b.data(), w, h, c, g1.data(), -0.2f);
    const auto ref = s2.reference(b.data(), w, h, c);
    const float v2 = s2.evaluate(a.data(), ref, g2.data(), -0.2f);
    EXPECT_EQ(std::memcmp(&v1, &v2, sizeof v1), 0) << w << "x" << h;
    EXPECT_EQ(std::memcmp(g1.data(), g2.data(), g1.size() * sizeof(float)), 0) << w << "x" << h;
  }
}

// The gradient is added to what the buffer holds (the trainer's L1 gradient): until 2026-11-26 it was
// written over it, and every training run lost its L1 gradient.
TEST(Ssim, GradientIsAddedToTheBuffer) {
  const int w = 16, h = 12, c = 3;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  std::vector<float> a(static_cast<std::size_t>(w) * h * c), b(a.size()), zero(a.size(), 0.0f), held(a.size());
  for (auto& v : a) v = u(rng);
  for (auto& v : b) v = u(rng);
  for (auto& v : held) v = u(rng) - 0.5f;
  std::vector<float> sum = held;
  Ssim<float> s;
  s.evaluate(a.data(), b.data(), w, h, c, zero.data(), -0.2f);
  s.evaluate(a.data(), b.data(), w, h, c, sum.data(), -0.2f);
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(sum[i], held[i] + zero[i]) << i;
}

TEST(Ssim, IdenticalImagesGiveOneAndZeroGradient) {
  const int w = 20, h = 20, c = 1;
  std::vector<double> a(static_cast<std::size_t>(w) * h), g(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) a[i] = 0.5 + 0.3 * std::sin(0.3 * static_cast<double>(i));
  Ssim<double> s;
  EXPECT_NEAR(s.evaluate(a.data(), a.data(), w, h, c, g.data()), 1.0, 1e-12);
  for (double v : g) EXPECT_NEAR(v, 0.0, 1e-12);  // SSIM is maximal at a == b
}

}  // namespace
}  // namespace d2gs
