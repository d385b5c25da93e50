// Gradient checks: every analytic gradient of the CPU rasterizer against central finite differences,
// in double, for the whole pipeline and for each stage separately (docs/rendering.md, "Tolerances").
// The smooth alpha cutoff is on (RenderOptions::smooth_cutoff) so that the loss is differentiable.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <random>
#include <string>

#include <gtest/gtest.h>
#include <omp.h>

#include "d2gs/render/cpu/binning.hpp"
#include "d2gs/render/cpu/composite.hpp"
#include "d2gs/render/cpu/projection.hpp"
#include "d2gs/render/cpu/sh.hpp"
#include "d2gs/render/raster_math.hpp"
#include "render_test_util.hpp"

namespace d2gs::test {
namespace {

// The checks render tiny images thousands of times: one thread avoids OpenMP start-up costs.
struct OneThread {
  int previous = omp_get_max_threads();
  OneThread() { omp_set_num_threads(1); }
  ~OneThread() { omp_set_num_threads(previous); }
};

using render::CameraParams;
using render::RenderOptions;
using namespace render::cpu;

std::vector<double> random_weights(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<double> w(n);
  for (auto& x : w) x = g(rng);
  return w;
}

double dot(const std::vector<double>& a, const std::vector<double>& b) {
  double s = 0;
  for (std::size_t i = 0; i < a.size(); ++i) s += a[i] * b[i];
  return s;
}

// Compares analytic[i] with the central difference of `loss` w.r.t. params[i]:
// |analytic - numeric| <= atol + rtol * max(|analytic|, |numeric|) for at least `min_pass` of them.
void check_gradient(const std::string& name, std::vector<double>& params, const std::vector<double>& analytic,
                    const std::function<double()>& loss, double h, double rtol, double atol,
                    double min_pass = 1.0, std::size_t stride = 1) {
  ASSERT_EQ(params.size(), analytic.size()) << name;
  std::size_t failures = 0, nonzero = 0;
  double worst = 0;
  std::size_t worst_i = 0;
  double worst_a = 0, worst_n = 0;
  std::size_t checked = 0;
  for (std::size_t i = 0; i < params.size(); i += stride) {
    ++checked;
    const double keep = params[i];
    params[i] = keep + h;
    const double lp = loss();
    params[i] = keep - h;
    const double lm = loss();
    params[i] = keep;
    const double numeric = (lp - lm) / (2 * h);
    const double a = analytic[i];
    if (a != 0 || numeric != 0) ++nonzero;
    const double err = std::abs(a - numeric);
    const double bound = atol + rtol * std::max(std::abs(a), std::abs(numeric));
    if (err > bound) ++failures;
    const double excess = err / bound;
    if (excess > worst) {
      worst = excess;
      worst_i = i;
      worst_a = a;
      worst_n = numeric;
    }
  }
  std::printf("  %-22s n=%5zu nonzero=%5zu failures=%zu worst err/bound=%.3g (i=%zu analytic=%.9g numeric=%.9g)\n",
              name.c_str(), checked, nonzero, failures, worst, worst_i, worst_a, worst_n);
  EXPECT_GE(nonzero, checked / 10) << name << ": too few non-zero gradients to be a test";
  EXPECT_LE(double(failures), (1.0 - min_pass) * double(checked))
      << name << ": worst analytic " << worst_a << " numeric " << worst_n << " at " << worst_i;
}

struct Case {
  CameraParams<double> cam;
  TestModel<double> model;
  RenderOptions options;
  std::vector<double> w_rgb, w_alpha, w_depth;
};

Case make_case(int width, int height, int n, unsigned seed, double max_opacity, bool smooth) {
  Case c;
  c.cam = test_camera<double>(width, height, seed);
  c.model = random_model(c.cam, n, seed + 1, max_opacity);
  c.options.smooth_cutoff = smooth;
  c.options.background = {0.2f, 0.5f, 0.9f};
  const std::size_t pixels = std::size_t(width) * height;
  c.w_rgb = random_weights(pixels * 3, seed + 2);
  c.w_alpha = random_weights(pixels, seed + 3);
  c.w_depth = random_weights(pixels, seed + 4);
  for (auto& w : c.w_depth) w *= 0.3;
  return c;
}

double render_loss(CpuRasterizerCore<double>& core, const Case& c) {
  const auto& out = core.forward(c.model.view(), c.model.multiplier.data(), c.cam, c.options);
  return dot(out.rgb, c.w_rgb) + dot(out.alpha, c.w_alpha) + dot(out.depth, c.w_depth);
}

// Tolerances per parameter (docs/rendering.md), central differences with step h = 1e-5 in double:
// |analytic - numeric| <= atol + rtol * max(|analytic|, |numeric|). atol covers the rounding noise of
// the difference quotient (loss ~ 1e3 * 1e-16 / 1e-5 ~ 1e-8); rtol the O(h^2) truncation error.
struct Tol {
  const char* name;
  double rtol, atol;
  std::size_t stride;  // every stride-th entry is checked (sh_rest: every 7th, all 45 slots covered)
};
constexpr double kStep = 1e-5;
constexpr Tol kModelTol[] = {{"means", 1e-4, 1e-7, 1},  {"log_scales", 1e-4, 1e-7, 1},
                             {"quats", 1e-4, 1e-7, 1},  {"opacity_logits", 1e-4, 1e-7, 1},
                             {"sh_dc", 1e-4, 1e-7, 1},  {"sh_rest", 1e-4, 1e-7, 7}};

void check_model_gradients(Case& c, double min_pass) {
  CpuRasterizerCore<double> core;
  render_loss(core, c);
  TestGrads<double> grads;
  grads.resize(c.model);
  core.backward(c.w_rgb.data(), c.w_alpha.data(), c.w_depth.data(), grads.view(), grads.mean2d_ndc.data());
  // The NDC screen gradient is the pixel gradient of mean2d scaled by W/2, H/2.
  const auto& pg = core.projected_grads().mean2d;
  for (std::size_t i = 0; i < c.model.size(); ++i) {
    EXPECT_EQ(grads.mean2d_ndc[i * 2], pg[i * 2] * 0.5 * c.cam.width);
    EXPECT_EQ(grads.mean2d_ndc[i * 2 + 1], pg[i * 2 + 1] * 0.5 * c.cam.height);
  }
  auto params = c.model.arrays();
  auto analytic = grads.arrays();
  for (std::size_t a = 0; a < params.size(); ++a)
    check_gradient(kModelTol[a].name, *params[a], *analytic[a], [&] { return render_loss(core, c); }, kStep,
                   kModelTol[a].rtol, kModelTol[a].atol, min_pass, kModelTol[a].stride);
}

TEST(RenderGradcheck, FullPipelineEveryParameter) {
  OneThread one;
  Case c = make_case(40, 30, 30, 11, 0.6, true);
  check_model_gradients(c, 1.0);
}

TEST(RenderGradcheck, FullPipelineSecondSceneLowerShDegree) {
  OneThread one;
  Case c = make_case(35, 37, 30, 23, 0.6, true);
  c.options.sh_degree = 2;
  check_model_gradients(c, 1.0);
}

// Hard cutoff, opaque Gaussians (early stop and the 0.99 clamp are exercised): the loss has jumps where
// an alpha crosses 1/255 or a transmittance crosses 1e-4, so a few parameters may disagree; the rest
// must match.
TEST(RenderGradcheck, HardCutoffWithEarlyStopMostParameters) {
  OneThread one;
  Case c = make_case(40, 30, 40, 37, 0.995, false);
  check_model_gradients(c, 0.97);
}

// ---- stage by stage ----

TEST(RenderGradcheck, ProjectionStage) {
  OneThread one;
  const auto cam = test_camera<double>(40, 30, 5);
  auto model = random_model(cam, 60, 6);
  const std::size_t n = model.size();
  const auto w_mean2d = random_weights(n * 2, 7), w_conic = random_weights(n * 3, 8);
  const auto w_depth = random_weights(n, 9), w_opacity = random_weights(n, 10);
  Projected<double> ref;
  project_forward(model.view(), model.multiplier.data(), cam, ref);
  const std::vector<int> visible(ref.radii.begin(), ref.radii.begin() + n);
  Projected<double> p;
  const auto loss = [&] {
    project_forward(model.view(), model.multiplier.data(), cam, p);
    double s = 0;
    for (std::size_t i = 0; i < n; ++i) {
      if (visible[i] <= 0) continue;
      for (int k = 0; k < 2; ++k) s += w_mean2d[i * 2 + k] * p.mean2d[i * 2 + k];
      for (int k = 0; k < 3; ++k) s += w_conic[i * 3 + k] * p.conic[i * 3 + k];
      s += w_depth[i] * p.depth[i] + w_opacity[i] * p.opacity[i];
    }
    return s;
  };
  ProjectedGrads<double> pg;
  pg.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 2; ++k) pg.mean2d[i * 2 + k] = w_mean2d[i * 2 + k];
    for (int k = 0; k < 3; ++k) pg.conic[i * 3 + k] = w_conic[i * 3 + k];
    pg.depth[i] = w_depth[i];
    pg.opacity[i] = w_opacity[i];
  }
  TestGrads<double> g;
  g.resize(model);
  project_backward(model.view(), model.multiplier.data(), cam, ref, pg, g.view());
  check_gradient("proj.means", model.means, g.means, loss, kStep, 1e-4, 1e-7);
  check_gradient("proj.log_scales", model.log_scales, g.log_scales, loss, kStep, 1e-4, 1e-7);
  check_gradient("proj.quats", model.quats, g.quats, loss, kStep, 1e-4, 1e-7);
  check_gradient("proj.opacity_logits", model.opacity_logits, g.opacity_logits, loss, kStep, 1e-4, 1e-7);
}

TEST(RenderGradcheck, ShStageEveryDegree) {
  OneThread one;
  const auto cam = test_camera<double>(40, 30, 12);
  for (int degree = 0; degree <= 3; ++degree) {
    auto model = random_model(cam, 30, 13 + degree, 0.6, false);
    const std::size_t n = model.size();
    const auto w = random_weights(n * 3, 20 + degree);
    Projected<double> p;
    p.resize(n);
    std::fill(p.radii.begin(), p.radii.end(), 1);
    const auto loss = [&] {
      sh_forward(model.view(), degree, cam, p);
      return dot(std::vector<double>(p.color.begin(), p.color.begin() + n * 3), w);
    };
    loss();
    TestGrads<double> g;
    g.resize(model);
    sh_backward(model.view(), degree, cam, p, w.data(), g.view());
    const std::string d = "sh" + std::to_string(degree) + ".";
    check_gradient(d + "sh_dc", model.sh_dc, g.sh_dc, loss, kStep, 1e-4, 1e-7);
    if (degree > 0) {
      check_gradient(d + "sh_rest", model.sh_rest, g.sh_rest, loss, kStep, 1e-4, 1e-7);
      check_gradient(d + "means", model.means, g.means, loss, kStep, 1e-4, 1e-7);
    }
  }
}

TEST(RenderGradcheck, CompositingStage) {
  OneThread one;
  const int width = 45, height = 35;
  const std::size_t n = 50;
  std::mt19937 rng(99);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  Projected<double> p;
  p.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    p.mean2d[i * 2] = -5 + (width + 10) * u(rng);
    p.mean2d[i * 2 + 1] = -5 + (height + 10) * u(rng);
    // cov = L L^T + 0.3 I with L lower triangular of size 1-6 px
    const double l0 = 1 + 5 * u(rng), l1 = 1 + 5 * u(rng), l2 = (u(rng) - 0.5) * 4;
    const double a = l0 * l0 + 0.3, b = l0 * l2, cc = l2 * l2 + l1 * l1 + 0.3;
    const double det = a * cc - b * b;
    p.conic[i * 3] = cc / det;
    p.conic[i * 3 + 1] = -b / det;
    p.conic[i * 3 + 2] = a / det;
    const double mid = 0.5 * (a + cc);
    p.radii[i] = int(std::ceil(3 * std::sqrt(mid + std::sqrt(std::max(0.1, mid * mid - det))))) + 1;
    p.opacity[i] = 0.05 + 0.6 * u(rng);
    for (int k = 0; k < 3; ++k) p.color[i * 3 + k] = u(rng);
    p.depth[i] = 1 + 10 * u(rng);
  }
  const double bg[3] = {0.3, 0.1, 0.7};
  const std::size_t pixels = std::size_t(width) * height;
  const auto w_rgb = random_weights(pixels * 3, 1), w_alpha = random_weights(pixels, 2),
             w_depth = random_weights(pixels, 3);
  Binning<double> bin;
  PixelState<double> state;
  std::vector<double> rgb(pixels * 3), alpha(pixels), depth(pixels);
  const auto loss = [&] {
    bin_gaussians(p, width, height, render::kSmoothAlphaLo, bin);
    composite_forward(bin, bg, true, rgb.data(), alpha.data(), depth.data(), state);
    return dot(rgb, w_rgb) + dot(alpha, w_alpha) + dot(depth, w_depth);
  };
  loss();
  std::vector<double> isect;
  ProjectedGrads<double> g;
  composite_backward(bin, bg, true, false, state, w_rgb.data(), w_alpha.data(), w_depth.data(), n, isect, g);
  const auto sized = [](std::vector<double>& v, std::size_t k) { v.resize(k); return v; };
  p.mean2d.resize(n * 2); p.conic.resize(n * 3); p.color.resize(n * 3);
  check_gradient("comp.mean2d", p.mean2d, sized(g.mean2d, n * 2), loss, kStep, 1e-4, 1e-7);
  // Conic entries are ~1e-2: a smaller step keeps the O(h^2) truncation error below rtol.
  check_gradient("comp.conic", p.conic, sized(g.conic, n * 3), loss, 1e-6, 1e-4, 1e-6);
  check_gradient("comp.opacity", p.opacity, sized(g.opacity, n), loss, kStep, 1e-4, 1e-7);
  check_gradient("comp.color", p.color, sized(g.color, n * 3), loss, kStep, 1e-4, 1e-7);
  check_gradient("comp.depth", p.depth, sized(g.depth, n), loss, kStep, 1e-4, 1e-7);
}

}  // namespace
}  // namespace d2gs::test
