// Rasterizer benchmark: forward and forward+backward of the CPU backend at LLFF 1/8 resolution
// (504 x 378) on a synthetic LLFF-like model (docs/benchmarks.md).
//
// Generator (seeded, deterministic): a forward-facing camera (fx = fy = 407.6, principal point at the
// image centre, identity pose). Depths z = 1.5 * (100/1.5)^(u^2), u ~ U(0,1): spread 1.5..100 with more
// near (median ~4). x/z, y/z uniform over 1.1x the field of view. Sizes as a kNN initialisation of a
// trained model would give: a screen-space standard deviation s ~ lognormal(median 1.5 px, sigma 0.6)
// clipped to [0.3, 40] px, world scale = s z / fx, per-axis factor exp(N(0, 0.3)); random rotations.
// Opacity = sigmoid(N(0.5, 1.5)); SH degree 3, DC ~ N(0, 0.5), rest ~ N(0, 0.1).
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include <chrono>

#include "d2gs/render/cpu/binning.hpp"
#include "d2gs/render/cpu/composite.hpp"
#include "d2gs/render/cpu/cpu_rasterizer.hpp"
#include "d2gs/render/cpu/projection.hpp"
#include "d2gs/render/cpu/sh.hpp"
#include "d2gs/render/raster_math.hpp"
#include "d2gs/render/rasterizer.hpp"

namespace {

using namespace d2gs;

constexpr int kWidth = 504, kHeight = 378;
constexpr double kFocal = 407.6;

Camera llff_camera() {
  Camera c;
  c.width = kWidth;
  c.height = kHeight;
  c.fx = c.fy = kFocal;
  c.cx = 0.5 * kWidth;
  c.cy = 0.5 * kHeight;
  return c;
}

Gaussians llff_like_model(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  std::normal_distribution<double> g(0.0, 1.0);
  Gaussians m;
  m.resize(n, 3);
  const int K = m.sh_rest_count();
  for (std::size_t i = 0; i < n; ++i) {
    const double a = u(rng);
    const double z = 1.5 * std::pow(100.0 / 1.5, a * a);
    const double x = (u(rng) - 0.5) * 1.1 * kWidth / kFocal * z;
    const double y = (u(rng) - 0.5) * 1.1 * kHeight / kFocal * z;
    m.means[i * 3] = float(x);
    m.means[i * 3 + 1] = float(y);
    m.means[i * 3 + 2] = float(z);
    const double s_px = std::clamp(1.5 * std::exp(0.6 * g(rng)), 0.3, 40.0);
    const double base = std::log(s_px * z / kFocal);
    for (int k = 0; k < 3; ++k) m.log_scales[i * 3 + k] = float(base + 0.3 * g(rng));
    for (int k = 0; k < 4; ++k) m.quats[i * 4 + k] = float(g(rng));
    m.opacity_logits[i] = float(0.5 + 1.5 * g(rng));
    for (int c = 0; c < 3; ++c) m.sh_dc[i * 3 + c] = float(0.5 * g(rng));
    for (int k = 0; k < K * 3; ++k) m.sh_rest[i * K * 3 + k] = float(0.1 * g(rng));
  }
  return m;
}

void run(benchmark::State& state, bool backward) {
  const auto n = static_cast<std::size_t>(state.range(0));
  const Gaussians model = llff_like_model(n, 1234);
  const auto camera = render::make_render_camera(llff_camera());
  auto rasterizer = render::make_cpu_rasterizer();
  render::RenderOptions options;
  std::vector<float> d_rgb(std::size_t(kWidth) * kHeight * 3);
  std::mt19937 rng(5);
  std::normal_distribution<float> g(0.0f, 1e-5f);
  for (auto& v : d_rgb) v = g(rng);
  std::size_t isects = 0, visible = 0;
  for (auto _ : state) {
    const auto& out = rasterizer->forward(model, nullptr, camera, options);
    isects = out.n_intersections;
    if (backward) {
      const auto& grads = rasterizer->backward(d_rgb.data(), nullptr, nullptr);
      benchmark::DoNotOptimize(grads.model.means.data());
    }
    benchmark::DoNotOptimize(out.rgb.data());
  }
  const auto& out = rasterizer->forward(model, nullptr, camera, options);
  for (int r : out.radii) visible += r > 0;
  state.counters["intersections"] = double(isects);
  state.counters["visible"] = double(visible);
}

// One forward + backward per iteration through the stage functions, timing each stage (counters in ms
// per iteration): where the time of BM_RenderForwardBackward goes.
void BM_RenderStages(benchmark::State& state) {
  using namespace d2gs::render::cpu;
  using Clock = std::chrono::steady_clock;
  const auto n = static_cast<std::size_t>(state.range(0));
  const Gaussians model = llff_like_model(n, 1234);
  const auto camera = render::make_render_camera(llff_camera());
  const ModelView<float> view = model_view(model);
  Gaussians grads;
  grads.resize(n, model.sh_degree);
  const ModelGradView<float> gview = model_grad_view(grads);
  Projected<float> proj;
  Binning<float> bin;
  PixelState<float> pixels;
  ProjectedGrads<float> pgrads;
  std::vector<float> isect_grads;
  const std::size_t np = std::size_t(kWidth) * kHeight;
  std::vector<float> rgb(np * 3), alpha(np), depth(np), d_rgb(np * 3);
  std::mt19937 rng(5);
  std::normal_distribution<float> g(0.0f, 1e-5f);
  for (auto& v : d_rgb) v = g(rng);
  const float bg[3] = {0, 0, 0};
  const float* no_multiplier = nullptr;
  const float* no_grad = nullptr;
  const char* names[] = {"project", "sh", "bin", "composite", "composite_bwd", "project_bwd", "sh_bwd"};
  double total[7] = {};
  for (auto _ : state) {
    auto t0 = Clock::now();
    int k = 0;
    const auto lap = [&] {
      const auto t1 = Clock::now();
      total[k++] += std::chrono::duration<double, std::milli>(t1 - t0).count();
      t0 = t1;
    };
    project_forward(view, no_multiplier, camera, proj);
    lap();
    sh_forward(view, 3, camera, proj);
    lap();
    bin_gaussians(proj, kWidth, kHeight, render::kAlphaMin, bin);
    lap();
    composite_forward(bin, bg, false, rgb.data(), alpha.data(), depth.data(), pixels);
    lap();
    composite_backward(bin, bg, false, false, pixels, d_rgb.data(), no_grad, no_grad, n, isect_grads, pgrads);
    lap();
    project_backward(view, no_multiplier, camera, proj, pgrads, gview);
    lap();
    sh_backward(view, 3, camera, proj, pgrads.color.data(), gview);
    lap();
    benchmark::DoNotOptimize(grads.means.data());
  }
  for (int k = 0; k < 7; ++k)
    state.counters[names[k]] = benchmark::Counter(total[k] / double(state.iterations()));
}

void BM_RenderForward(benchmark::State& state) { run(state, false); }
void BM_RenderForwardBackward(benchmark::State& state) { run(state, true); }

BENCHMARK(BM_RenderForward)->Arg(100000)->Arg(300000)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RenderForwardBackward)->Arg(100000)->Arg(300000)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RenderStages)->Arg(100000)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
