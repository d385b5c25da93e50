// Bit-identical results whatever the thread count, float/double agreement, workspace reuse, and the
// public API's edge cases.
#include <omp.h>

#include <cmath>
#include <cstring>

#include <gtest/gtest.h>

#include "d2gs/render/rasterizer.hpp"
#include "render_test_util.hpp"

namespace d2gs::test {
namespace {

Gaussians to_gaussians(const TestModel<float>& m) {
  Gaussians g;
  g.resize(m.size(), m.sh_degree);
  g.means = m.means; g.log_scales = m.log_scales; g.quats = m.quats;
  g.opacity_logits = m.opacity_logits; g.sh_dc = m.sh_dc; g.sh_rest = m.sh_rest;
  return g;
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

struct RunResult {
  std::vector<float> rgb, alpha, depth;
  std::vector<int> radii;
  Gaussians grads;
  std::vector<float> ndc;
};

RunResult render_once(render::Rasterizer& r, const Gaussians& model, const std::vector<float>& mult,
                const render::RenderCamera& cam, const std::vector<float>& w) {
  render::RenderOptions options;
  options.background = {0.1f, 0.2f, 0.3f};
  const auto& out = r.forward(model, mult.data(), cam, options);
  RunResult run{out.rgb, out.alpha, out.depth, out.radii, {}, {}};
  const std::size_t pixels = out.alpha.size();
  const auto& g = r.backward(w.data(), w.data() + pixels * 3, w.data() + pixels * 4);
  run.grads = g.model;
  run.ndc = g.grad_mean2d_ndc;
  return run;
}

TEST(RenderDeterminism, BitIdenticalAcrossThreadCounts) {
  const auto cam = test_camera<float>(200, 150, 3);
  const auto model32 = random_model(cam, 6000, 4, 0.99);
  const Gaussians model = to_gaussians(model32);
  std::vector<float> w(200 * 150 * 5);
  for (std::size_t i = 0; i < w.size(); ++i) w[i] = std::sin(float(i) * 0.37f);
  const int previous = omp_get_max_threads();
  std::vector<RunResult> runs;
  for (int threads : {1, 2, 3}) {
    omp_set_num_threads(threads);
    auto r = render::make_cpu_rasterizer();
    runs.push_back(render_once(*r, model, model32.multiplier, cam, w));
    runs.push_back(render_once(*r, model, model32.multiplier, cam, w));  // reused workspace
  }
  omp_set_num_threads(previous);
  const RunResult& ref = runs[0];
  double sum = 0;
  for (float v : ref.grads.means) sum += std::abs(v);
  EXPECT_GT(sum, 0.0);
  for (std::size_t k = 1; k < runs.size(); ++k) {
    const RunResult& r = runs[k];
    EXPECT_TRUE(same_bits(r.rgb, ref.rgb)) << k;
    EXPECT_TRUE(same_bits(r.alpha, ref.alpha)) << k;
    EXPECT_TRUE(same_bits(r.depth, ref.depth)) << k;
    EXPECT_EQ(r.radii, ref.radii) << k;
    EXPECT_TRUE(same_bits(r.grads.means, ref.grads.means)) << k;
    EXPECT_TRUE(same_bits(r.grads.log_scales, ref.grads.log_scales)) << k;
    EXPECT_TRUE(same_bits(r.grads.quats, ref.grads.quats)) << k;
    EXPECT_TRUE(same_bits(r.grads.opacity_logits, ref.grads.opacity_logits)) << k;
    EXPECT_TRUE(same_bits(r.grads.sh_dc, ref.grads.sh_dc)) << k;
    EXPECT_TRUE(same_bits(r.grads.sh_rest, ref.grads.sh_rest)) << k;
    EXPECT_TRUE(same_bits(r.ndc, ref.ndc)) << k;
  }
}

// The float renderer (fast exp, float arithmetic) agrees with the double instantiation.
TEST(RenderDeterminism, FloatMatchesDouble) {
  const auto camd = test_camera<double>(96, 64, 8);
  const auto md = random_model(camd, 400, 9, 0.9);
  const auto mf = md.cast<float>();
  const auto camf = test_camera<float>(96, 64, 8);
  render::RenderOptions options;
  render::cpu::CpuRasterizerCore<float> cf;
  render::cpu::CpuRasterizerCore<double> cd;
  const auto& of = cf.forward(mf.view(), mf.multiplier.data(), camf, options);
  const auto& od = cd.forward(md.view(), md.multiplier.data(), camd, options);
  expect_image_close_to_double(of.rgb, od.rgb);
  // Gradients: relative L2 difference per parameter array.
  std::vector<double> wd(od.rgb.size());
  for (std::size_t i = 0; i < wd.size(); ++i) wd[i] = std::cos(double(i) * 0.11);
  std::vector<float> wf(wd.begin(), wd.end());
  TestGrads<float> gf;
  gf.resize(mf);
  TestGrads<double> gd;
  gd.resize(md);
  cf.backward(wf.data(), nullptr, nullptr, gf.view(), nullptr);
  cd.backward(wd.data(), nullptr, nullptr, gd.view(), nullptr);
  auto af = gf.arrays();
  auto ad = gd.arrays();
  for (std::size_t a = 0; a < af.size(); ++a) EXPECT_LT(rel_l2(*af[a], *ad[a]), 1e-3) << "array " << a;
}

TEST(RenderApi, EmptyModelAndNullGradients) {
  Gaussians model;
  model.resize(0, 0);
  Camera camera;
  camera.width = 33;
  camera.height = 17;
  camera.fx = camera.fy = 30;
  camera.cx = 16.5;
  camera.cy = 8.5;
  auto r = render::make_cpu_rasterizer();
  render::RenderOptions options;
  options.background = {1.0f, 0.5f, 0.0f};
  const auto& out = r->forward(model, nullptr, render::make_render_camera(camera), options);
  ASSERT_EQ(out.rgb.size(), 33u * 17u * 3u);
  EXPECT_EQ(out.rgb[0], 1.0f);
  EXPECT_EQ(out.rgb[1], 0.5f);
  EXPECT_EQ(out.alpha[5], 0.0f);
  const auto& g = r->backward(nullptr, nullptr, nullptr);
  EXPECT_EQ(g.model.size(), 0u);
}

// A single opaque isotropic Gaussian on the optical axis lands on the principal point: with d2gs's
// pixel centres at +0.5, a Gaussian at cx = 16 is centred between pixels 15 and 16.
TEST(RenderApi, PixelAlignment) {
  Gaussians model;
  model.resize(1, 0);
  model.means = {0.0f, 0.0f, 5.0f};
  model.log_scales = {std::log(0.05f), std::log(0.05f), std::log(0.05f)};
  model.opacity_logits = {4.0f};
  model.sh_dc = {1.0f, 1.0f, 1.0f};
  Camera camera;
  camera.width = 32;
  camera.height = 32;
  camera.fx = camera.fy = 100;
  camera.cx = 16.0;
  camera.cy = 16.0;
  auto r = render::make_cpu_rasterizer();
  const auto& out = r->forward(model, nullptr, render::make_render_camera(camera), {});
  EXPECT_EQ(out.radii[0] > 0, true);
  const auto a = [&](int x, int y) { return out.alpha[y * 32 + x]; };
  EXPECT_FLOAT_EQ(a(15, 15), a(16, 16));
  EXPECT_FLOAT_EQ(a(15, 16), a(16, 15));
  EXPECT_GT(a(15, 15), a(14, 15));
  EXPECT_FLOAT_EQ(a(14, 15), a(17, 15));
}

}  // namespace
}  // namespace d2gs::test
