// Rasterizer benchmark: forward and forward+backward of the CPU backend at LLFF 1/8 resolution
// (504 x 378) on the synthetic LLFF-like model of llff_like_model.hpp (docs/benchmarks.md).
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
#include "llff_like_model.hpp"

namespace {

using namespace d2gs;
using bench::kHeight;
using bench::kWidth;
using bench::llff_camera;
using bench::llff_like_model;

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
