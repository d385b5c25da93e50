// The kernel rasterizer (render/kernels/kernel_rasterizer.hpp): the Rasterizer interface over the CUDA
// backend's stages, which `d2gs render/eval --device cuda` use. Against the CPU rasterizer on random
// scenes and fern: through the emulator on every machine (forward bit for bit, as the stages and the
// compositing are; the backward's sums run in another order, so within 1e-5 relative L2 per array), and
// on the GPU when there is one (forward within 1e-5 relative L2 and 1e-3 per value, backward within 1e-4:
// CUDA's expf is not glibc's, and a cutoff or clamp can fall the other way for a few pixels).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "cuda/stage_compare.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/stages.hpp"
#include "d2gs/render/device_choice.hpp"
#include "d2gs/render/kernels/kernel_rasterizer.hpp"
#include "d2gs/render/rasterizer.hpp"

namespace d2gs::test {
namespace {

Gaussians to_gaussians(const TestModel<float>& m) {
  Gaussians g;
  g.resize(m.size(), m.sh_degree);
  g.means = m.means;
  g.log_scales = m.log_scales;
  g.quats = m.quats;
  g.opacity_logits = m.opacity_logits;
  g.sh_dc = m.sh_dc;
  g.sh_rest = m.sh_rest;
  return g;
}

// Relative L2 distance and largest absolute difference (stage_compare.hpp's measures).
double rel_l2(const std::vector<float>& got, const std::vector<float>& want) {
  return closeness(got, want, want.size()).rel_l2;
}
double max_abs_diff(const std::vector<float>& got, const std::vector<float>& want) {
  return diff(got.data(), want.data(), want.size()).max_abs;
}

struct Scene {
  std::string label;
  Gaussians model;
  std::vector<float> multiplier;  // empty: none
  render::RenderCamera camera;
  render::RenderOptions options;
};

std::vector<Scene> scenes() {
  std::vector<Scene> out;
  {
    Scene s;
    s.label = "random 64x48 N400, background, SH 3";
    s.camera = test_camera<float>(64, 48, 11);
    s.model = to_gaussians(random_model<float>(s.camera, 400, 12, 0.8));
    s.options.background = {0.2f, 0.4f, 0.6f};
    out.push_back(std::move(s));
  }
  {
    Scene s;
    s.label = "random 61x45 N300, active SH 1, multiplier, clamp pass-through";
    s.camera = test_camera<float>(61, 45, 13);
    const auto m = random_model<float>(s.camera, 300, 14, 0.99);
    s.model = to_gaussians(m);
    s.multiplier = m.multiplier;
    s.options.sh_degree = 1;
    s.options.alpha_clamp_pass_through = true;
    out.push_back(std::move(s));
  }
  for (const FernCase& fern : {load_fern_case(), load_fern_published_case()}) {
    Scene s;
    s.label = "fern (" + std::to_string(fern.model.size()) + " Gaussians) view 0";
    s.camera = fern.cameras[0];
    s.model = to_gaussians(fern.model);
    s.multiplier = fern.model.multiplier;
    out.push_back(std::move(s));
  }
  return out;
}

// Every gradient array of `got` beside the same of `want`, by name.
using ArrayPair = std::pair<const char*, std::pair<const std::vector<float>*, const std::vector<float>*>>;
std::array<ArrayPair, 7> gradient_arrays(const render::RenderGradients& got, const render::RenderGradients& want) {
  return {{{"means", {&got.model.means, &want.model.means}},
           {"log_scales", {&got.model.log_scales, &want.model.log_scales}},
           {"quats", {&got.model.quats, &want.model.quats}},
           {"opacity_logits", {&got.model.opacity_logits, &want.model.opacity_logits}},
           {"sh_dc", {&got.model.sh_dc, &want.model.sh_dc}},
           {"sh_rest", {&got.model.sh_rest, &want.model.sh_rest}},
           {"grad_mean2d_ndc", {&got.grad_mean2d_ndc, &want.grad_mean2d_ndc}}}};
}

// Forward and backward of every scene through the CPU rasterizer and `make` (one rasterizer reused across
// scenes, as a command reuses it across views).
void compare(render::Rasterizer& kernels, bool exact_forward, double forward_abs, double backward_rel_l2) {
  auto cpu = render::make_cpu_rasterizer();
  for (const Scene& s : scenes()) {
    const float* mult = s.multiplier.empty() ? nullptr : s.multiplier.data();
    const render::RenderOutputs want = cpu->forward(s.model, mult, s.camera, s.options);
    const render::RenderOutputs got = kernels.forward(s.model, mult, s.camera, s.options);
    ASSERT_EQ(got.width, want.width) << s.label;
    ASSERT_EQ(got.height, want.height) << s.label;
    ASSERT_EQ(got.rgb.size(), want.rgb.size()) << s.label;
    if (exact_forward) {
      EXPECT_EQ(got.rgb, want.rgb) << s.label;
      EXPECT_EQ(got.alpha, want.alpha) << s.label;
      EXPECT_EQ(got.depth, want.depth) << s.label;
      EXPECT_EQ(got.radii, want.radii) << s.label;
      EXPECT_EQ(got.n_intersections, want.n_intersections) << s.label;
    } else {
      // A few pixels differ more than the rest: their Gaussians' alpha sits at a cutoff or clamp that the
      // projections' last-bit differences put on the other side (2.9e-5 in rgb on fern's published cloud, H200).
      const double rgb_max = max_abs_diff(got.rgb, want.rgb), rgb_l2 = rel_l2(got.rgb, want.rgb);
      const double alpha_max = max_abs_diff(got.alpha, want.alpha), depth_l2 = rel_l2(got.depth, want.depth);
      std::printf("%s [%s]: forward rgb max %.2g rel L2 %.2g, alpha max %.2g, depth rel L2 %.2g\n", s.label.c_str(),
                  kernels.name(), rgb_max, rgb_l2, alpha_max, depth_l2);
      EXPECT_LE(rgb_max, forward_abs) << s.label;
      EXPECT_LE(alpha_max, forward_abs) << s.label;
      EXPECT_LE(rgb_l2, 1e-5) << s.label;
      EXPECT_LE(depth_l2, 1e-5) << s.label;
    }
    // dL/d rgb, alpha, depth: random, fixed per scene.
    const std::size_t pixels = want.alpha.size();
    std::mt19937 rng(7);
    std::normal_distribution<float> g(0.0f, 1.0f);
    std::vector<float> d_rgb(pixels * 3), d_alpha(pixels), d_depth(pixels);
    for (auto& v : d_rgb) v = g(rng);
    for (auto& v : d_alpha) v = 0.5f * g(rng);
    for (auto& v : d_depth) v = 0.1f * g(rng);
    const render::RenderGradients gw = cpu->backward(d_rgb.data(), d_alpha.data(), d_depth.data());
    const render::RenderGradients gg = kernels.backward(d_rgb.data(), d_alpha.data(), d_depth.data());
    ASSERT_EQ(gg.model.size(), gw.model.size()) << s.label;
    ASSERT_EQ(gg.model.sh_degree, gw.model.sh_degree) << s.label;
    const auto arrays = gradient_arrays(gg, gw);
    std::printf("%s [%s]: backward rel L2", s.label.c_str(), kernels.name());
    for (const auto& [name, pair] : arrays) {
      ASSERT_EQ(pair.first->size(), pair.second->size()) << s.label << " " << name;
      const double e = rel_l2(*pair.first, *pair.second);
      EXPECT_LE(e, backward_rel_l2) << s.label << " " << name;
      std::printf(" %s %.2g", name, e);
    }
    std::printf("\n");
  }
}

TEST(EmulatedRasterizer, EqualsTheCpuRasterizer) {
  auto kernels = render::kernels::make_kernel_rasterizer(render::kernels::make_emulated_stages(), cpu_level_fuses());
  compare(*kernels, true, 0.0, 1e-5);
}

// Element by element, with the L1 loss's gradient shape (±1/N per value) and SH degree 0 (a run's first
// 1 000 iterations) and 3: a gradient the CPU gives as exactly zero is zero here too, and no value of
// some size changes sign. Adam scales each parameter's steps by its own gradient's history, so a tiny
// non-zero where the CPU has zero would become a full-size step; relative L2 per array cannot see that.
TEST(EmulatedRasterizer, GradientsVanishWhereTheCpusDoAndKeepTheirSigns) {
  auto cpu = render::make_cpu_rasterizer();
  auto kernels = render::kernels::make_kernel_rasterizer(render::kernels::make_emulated_stages(), cpu_level_fuses());
  for (const Scene& scene : scenes()) {
    for (const int degree : {0, 3}) {
      Scene s = scene;
      s.options.sh_degree = degree;
      const float* mult = s.multiplier.empty() ? nullptr : s.multiplier.data();
      const std::size_t values = cpu->forward(s.model, mult, s.camera, s.options).rgb.size();
      kernels->forward(s.model, mult, s.camera, s.options);
      std::mt19937 rng(11);
      std::vector<float> d_rgb(values);
      for (auto& v : d_rgb) v = ((rng() & 1) ? 1.0f : -1.0f) / static_cast<float>(values);
      const render::RenderGradients want = cpu->backward(d_rgb.data(), nullptr, nullptr);
      const render::RenderGradients got = kernels->backward(d_rgb.data(), nullptr, nullptr);
      const auto arrays = gradient_arrays(got, want);
      for (const auto& [name, pair] : arrays) {
        const std::vector<float>& g = *pair.first;
        const std::vector<float>& w = *pair.second;
        ASSERT_EQ(g.size(), w.size()) << s.label << " " << name;
        float largest = 0.0f;
        for (const float v : w) largest = std::max(largest, std::fabs(v));
        std::size_t zero_mismatches = 0, sign_flips = 0, zeros = 0;
        for (std::size_t i = 0; i < w.size(); ++i) {
          zeros += w[i] == 0.0f;
          zero_mismatches += (w[i] == 0.0f) != (g[i] == 0.0f);
          sign_flips += std::fabs(w[i]) > 1e-4f * largest && (w[i] > 0.0f) != (g[i] > 0.0f);
        }
        EXPECT_EQ(zero_mismatches, 0u) << s.label << ", SH " << degree << ", " << name << " (" << zeros << " zeros on the CPU)";
        EXPECT_EQ(sign_flips, 0u) << s.label << ", SH " << degree << ", " << name;
        if (degree == 0 && std::string(name) == "sh_rest") {
          EXPECT_EQ(zeros, w.size()) << s.label;
        }
      }
    }
  }
}

TEST(EmulatedRasterizer, RefusesAMissingStageRunner) {
  EXPECT_THROW(render::kernels::make_kernel_rasterizer(nullptr, true), Error);
}

TEST(DeviceRasterizer, EqualsTheCpuRasterizerWithinFloatTolerance) {
  if (cuda::device_count() == 0) GTEST_SKIP() << cuda::describe_device();
  const render::DeviceChoice choice = render::choose_device(render::DeviceRequest::Cuda, render::DeviceWork::Render);
  ASSERT_EQ(choice.device, render::Device::Cuda);
  auto kernels = render::make_rasterizer(choice);
  compare(*kernels, false, 1e-3, 1e-4);
}

}  // namespace
}  // namespace d2gs::test
