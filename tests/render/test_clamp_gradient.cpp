// The two rules for the gradient through the alpha clamp alpha = min(0.99, o G) (raster_math.hpp).
// Finite differences cannot check the original rasterizer's pass-through rule (it is not the derivative of
// the forward pass), so its formula is checked directly on one Gaussian, and both rules are checked to
// agree exactly where nothing is clamped.
#include <cmath>
#include <cstring>

#include <gtest/gtest.h>

#include "d2gs/render/raster_math.hpp"
#include "d2gs/render/rasterizer.hpp"
#include "render_test_util.hpp"

namespace d2gs::test {
namespace {

constexpr int kSize = 64;

Camera square_camera() {
  Camera camera;
  camera.width = camera.height = kSize;
  camera.fx = camera.fy = 100;
  camera.cx = camera.cy = 0.5 * kSize + 0.3;
  return camera;
}

// One isotropic Gaussian of about 10 px standard deviation in the middle of the image.
Gaussians one_gaussian(float opacity_logit) {
  Gaussians model;
  model.resize(1, 0);
  model.means = {0.0f, 0.0f, 5.0f};
  model.log_scales = {std::log(0.5f), std::log(0.5f), std::log(0.5f)};
  model.opacity_logits = {opacity_logit};
  model.sh_dc = {1.0f, 0.4f, -0.3f};
  return model;
}

TEST(AlphaClampGradient, ScalarRule) {
  EXPECT_TRUE(render::alpha_clamp_gradient_passes(0.5f, false));
  EXPECT_FALSE(render::alpha_clamp_gradient_passes(0.995f, false));
  EXPECT_FALSE(render::alpha_clamp_gradient_passes(1.3, false));
  EXPECT_TRUE(render::alpha_clamp_gradient_passes(0.995f, true));
  EXPECT_TRUE(render::alpha_clamp_gradient_passes(1.3, true));
}

// L = sum_p w . rgb_p for one Gaussian over a background: C_p = alpha_p c + (1 - alpha_p) bg, so
// dL/dalpha_p = w . (c - bg) =: s at every composited pixel, and with o the effective opacity
// (sigmoid(logit) x multiplier) each composited pixel adds G_p s to dL/do when its gradient passes the clamp.
// The two rules differ exactly at the clamped pixels (o G_p >= 0.99, where the forward alpha is 0.99):
// pass-through minus exact = sum over them of G_p s, times d o / d logit. G_p comes from a second render of
// the same Gaussian at opacity 1/2, where nothing clamps (G_p = 2 alpha_p). The exact rule itself is the
// derivative of the forward pass, checked by finite differences in test_gradcheck.cpp.
TEST(AlphaClampGradient, PassThroughAddsTheClampedPixelsOpacityGradient) {
  const Camera camera = square_camera();
  const auto cam = render::make_render_camera(camera);
  render::RenderOptions options;
  options.background = {0.1f, 0.2f, 0.3f};
  const float w[3] = {1.0f, 0.5f, 0.25f};
  std::vector<float> d_rgb(kSize * kSize * 3);
  for (std::size_t i = 0; i < d_rgb.size(); ++i) d_rgb[i] = w[i % 3];

  // G_p and the colour from the unclamped render (opacity 1/2).
  auto r = render::make_cpu_rasterizer();
  const auto& ref = r->forward(one_gaussian(0.0f), nullptr, cam, options);
  std::vector<double> G(kSize * kSize);
  for (int p = 0; p < kSize * kSize; ++p) G[p] = 2.0 * ref.alpha[p];
  const int centre = (kSize / 2) * kSize + kSize / 2;
  double s = 0.0;
  for (int k = 0; k < 3; ++k) {
    const double a = ref.alpha[centre];
    const double c = (ref.rgb[centre * 3 + k] - (1.0 - a) * options.background[k]) / a;
    s += w[k] * (c - options.background[k]);
  }

  // DropGaussian's compensation makes the effective opacity 0.99 x 1.25 > 1: a disc of clamped pixels.
  const float logit = std::log(0.99f / 0.01f);
  const Gaussians model = one_gaussian(logit);
  const std::vector<float> multiplier = {1.25f};
  const double o_sig = 1.0 / (1.0 + std::exp(-double(logit)));
  const double chain = multiplier[0] * o_sig * (1.0 - o_sig);  // d o / d logit
  double grad[2] = {0.0, 0.0}, clamped_sum = 0.0;
  int clamped = 0;
  for (int pass = 0; pass < 2; ++pass) {
    options.alpha_clamp_pass_through = pass == 1;
    const auto& out = r->forward(model, multiplier.data(), cam, options);
    if (pass == 0)
      for (int p = 0; p < kSize * kSize; ++p)
        if (out.alpha[p] >= float(render::kAlphaMax) - 1e-6f) clamped_sum += G[p], ++clamped;
    grad[pass] = r->backward(d_rgb.data(), nullptr, nullptr).model.opacity_logits[0];
  }
  ASSERT_GT(clamped, 50);
  const double expect = clamped_sum * s * chain;
  EXPECT_GT(grad[1] - grad[0], 0.1 * std::abs(grad[0]));  // a real effect, not rounding
  EXPECT_NEAR(grad[1] - grad[0], expect, 1e-4 * std::abs(expect));
}

// Where no pixel is clamped the two rules are the same computation: every gradient bit-identical. Where
// pixels are clamped, the colour gradients (which do not go through alpha) still agree and the others differ.
TEST(AlphaClampGradient, RulesAgreeExactlyWithoutClampingAndDifferWithIt) {
  const auto cam = test_camera<float>(120, 90, 5);
  // (largest opacity, multiplier): 0.6 never clamps; 0.9 x 1.25 (DropGaussian's compensation) often does.
  for (const auto& [max_opacity, factor] : {std::pair{0.6, 1.0f}, std::pair{0.9, 1.25f}}) {
    SCOPED_TRACE(max_opacity);
    const auto m = random_model(cam, 800, 6, max_opacity);
    Gaussians model;
    model.resize(m.size(), 3);
    model.means = m.means;
    model.log_scales = m.log_scales;
    model.quats = m.quats;
    model.opacity_logits = m.opacity_logits;
    model.sh_dc = m.sh_dc;
    model.sh_rest = m.sh_rest;
    std::vector<float> multiplier(m.size(), factor);
    std::vector<float> d_rgb(120 * 90 * 3);
    for (std::size_t i = 0; i < d_rgb.size(); ++i) d_rgb[i] = std::sin(float(i) * 0.37f);
    Gaussians grads[2];
    for (int pass = 0; pass < 2; ++pass) {
      auto r = render::make_cpu_rasterizer();
      render::RenderOptions options;
      options.alpha_clamp_pass_through = pass == 1;
      r->forward(model, multiplier.data(), cam, options);
      grads[pass] = r->backward(d_rgb.data(), nullptr, nullptr).model;
    }
    const auto same = [](const std::vector<float>& a, const std::vector<float>& b) {
      return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
    };
    EXPECT_TRUE(same(grads[0].sh_dc, grads[1].sh_dc));
    EXPECT_TRUE(same(grads[0].sh_rest, grads[1].sh_rest));
    const bool clamps = max_opacity * factor > render::kAlphaMax;
    EXPECT_EQ(same(grads[0].opacity_logits, grads[1].opacity_logits), !clamps);
    EXPECT_EQ(same(grads[0].means, grads[1].means), !clamps);
    EXPECT_EQ(same(grads[0].log_scales, grads[1].log_scales), !clamps);
  }
}

}  // namespace
}  // namespace d2gs::test
