// The CUDA backend's rasterizer stages on a GPU (docs/benchmarks.md): projection, SH, tile intersection
// with CUB's radix sort, alpha compositing forward, compositing backward and the projection and SH
// backward, chained on the device (render/kernels/pipeline.hpp), at LLFF 1/8 resolution (504 x 378) on
// the synthetic LLFF-like model of llff_like_model.hpp, SH degree 3 in use.
//
// Two figures per size:
//   BM_CudaRasterizer/N/resident:1  timing mode (StageRunner::set_timing_mode): the model stays on the device,
//                                   no stage output is copied back; what is timed is the kernels, their
//                                   launches, the upload of dL/d rgb (2.3 MB) and the one intersection
//                                   count each forward reads back, ended by a device synchronisation.
//   BM_CudaRasterizer/N/resident:0  the same chain with the model uploaded and every stage's output copied
//                                   to the host, as the parity tests run it.
// Counters: intersections, visible Gaussians, and device_MiB, the device memory in use after the runs
// (cudaMemGetInfo) less that before the runner existed: the pipeline's arrays only grow, so this is their
// peak, plus CUB's temporary storage. Without a GPU every benchmark is skipped with the reason.
#include <benchmark/benchmark.h>

#include <cstddef>
#include <memory>
#include <random>
#include <vector>

#include "d2gs/render/cpu/cpu_rasterizer.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/stages.hpp"
#include "d2gs/render/rasterizer.hpp"
#include "llff_like_model.hpp"

namespace {

using namespace d2gs;

void BM_CudaRasterizer(benchmark::State& state) {
  if (cuda::device_count() == 0) {
    state.SkipWithError(cuda::describe_device().c_str());
    for (auto _ : state) {
    }
    return;
  }
  const auto n = static_cast<std::size_t>(state.range(0));
  const bool resident = state.range(1) != 0;
  const Gaussians model = bench::llff_like_model(n, 1234);
  const auto view = render::cpu::model_view(model);
  const auto camera = render::make_render_camera(bench::llff_camera());
  std::vector<float> d_rgb(std::size_t(bench::kWidth) * bench::kHeight * 3);
  std::mt19937 rng(5);
  std::normal_distribution<float> g(0.0f, 1e-5f);
  for (auto& v : d_rgb) v = g(rng);

  const std::size_t memory_before = cuda::device_memory_in_use();
  auto runner = cuda::make_device_stages();
  render::kernels::StageOptions options;
  options.active_degree = 3;
  render::kernels::CompositeOptions composite;
  // The first chain outside timing mode: its outputs give the counters, and it warms the device up.
  const auto& forward = runner->forward(view, nullptr, camera, options);
  std::size_t visible = 0;
  for (int r : forward.radii) visible += r > 0;
  const std::size_t intersections = forward.isect_gaussians.size();
  runner->composite(composite);
  runner->composite_backward(d_rgb.data(), nullptr, nullptr);
  runner->backward_from_composite();
  runner->set_timing_mode(resident);
  for (auto _ : state) {
    runner->forward(view, nullptr, camera, options);
    runner->composite(composite);
    runner->composite_backward(d_rgb.data(), nullptr, nullptr);
    benchmark::DoNotOptimize(runner->backward_from_composite());
    runner->synchronize();
  }
  state.counters["intersections"] = double(intersections);
  state.counters["visible"] = double(visible);
  state.counters["device_MiB"] = double(cuda::device_memory_in_use() - memory_before) / (1024.0 * 1024.0);
}

}  // namespace

BENCHMARK(BM_CudaRasterizer)
    ->ArgsProduct({{100000, 1000000}, {1, 0}})
    ->ArgNames({"N", "resident"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

BENCHMARK_MAIN();
