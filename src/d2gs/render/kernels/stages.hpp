#pragma once
// The CUDA backend's per-Gaussian stages and binning as one interface with two executions: the GPU
// (cuda::make_device_stages, render/cuda/stages.hpp) and the CPU emulation of the same kernels
// (make_emulated_stages). Inputs and outputs are host arrays, so tests compare every stage's output with
// the CPU reference backend; inside, the stages run back to back on the device (kernels/pipeline.hpp)
// with one scalar read back (the number of intersections); compositing follows on the same device arrays.
#include <cstdint>
#include <memory>
#include <vector>

#include "d2gs/render/cpu/types.hpp"
#include "d2gs/render/kernels/emulate.hpp"

namespace d2gs::render::kernels {

struct StageOptions {
  int active_degree = 0;               // SH degree in use (<= the model's)
  double alpha_min = 1.0 / 255.0;      // compositing cutoff: 1/255, or kSmoothAlphaLo (smooth cutoff)
};

// Every stage's outputs, downloaded.
struct ForwardStages {
  int tiles_x = 0, tiles_y = 0;
  // projection (cpu::project_forward)
  std::vector<float> mean2d, conic, depth, opacity;
  std::vector<int> radii;
  // SH (cpu::sh_forward)
  std::vector<float> color;
  std::vector<std::uint8_t> color_clamped;
  // tile intersection (cpu::bin_gaussians)
  std::vector<int> rects;          // N x 4
  std::vector<int> tile_counts;    // N
  std::vector<int> isect_offsets;  // N: inclusive scan of tile_counts
  std::vector<std::uint64_t> isect_keys;  // M, sorted: tile << 32 | depth bits
  std::vector<int> isect_gaussians;       // M, in key order
  std::vector<int> tile_ranges;           // tiles x 2: [begin, end) into the sorted intersections
};

// dL/d of the projected quantities (what compositing's backward produces), N-sized host arrays.
struct ProjectedGradsIn {
  const float* mean2d = nullptr;   // N x 2
  const float* conic = nullptr;    // N x 3
  const float* depth = nullptr;    // N
  const float* opacity = nullptr;  // N
  const float* color = nullptr;    // N x 3
};

// Model-shaped gradients, downloaded.
struct BackwardStages {
  std::vector<float> means, log_scales, quats, opacity_logits, sh_dc, sh_rest;
};

// Alpha compositing (kernels/composite_kernels.hpp) of the last forward() or load_projected().
struct CompositeOptions {
  float background[3] = {0, 0, 0};
  bool smooth_cutoff = false;       // raster_math.hpp's smooth cutoff (gradient checks); forward's alpha_min then
                                    // kSmoothAlphaLo
  bool clamp_pass_through = false;  // the gradient through alpha = min(0.99, o G) (backward only)
  // Whether the per-pixel multiply-adds are fused, as the CPU tile loops' fmadd at x86-64-v3/v4 (and the
  // natural choice on a GPU), or not, as at the SSE2 baseline (composite_math.hpp).
  bool fused_multiply_add = true;
};

// Compositing's outputs, downloaded (H x W, rgb interleaved): cpu::composite_forward's and its PixelState.
struct CompositeStages {
  std::vector<float> rgb, alpha, depth, final_transmittance;
  std::vector<int> n_contrib;
};

// dL/d of the projected quantities from compositing's backward, downloaded (N-sized, zero for the
// Gaussians of no tile): cpu::composite_backward's ProjectedGrads.
struct CompositeGrads {
  std::vector<float> mean2d, conic, depth, opacity, color;
};

// Projected Gaussians and sorted tile lists given as host arrays, for compositing alone (tests feed it the
// CPU stages' outputs, so that compositing is compared on identical inputs).
struct ProjectedIn {
  int width = 0, height = 0;
  std::size_t n = 0;
  const float* mean2d = nullptr;   // N x 2
  const float* conic = nullptr;    // N x 3
  const float* depth = nullptr;    // N
  const float* opacity = nullptr;  // N
  const float* color = nullptr;    // N x 3
  std::size_t intersections = 0;
  const int* isect_gaussians = nullptr;  // M: every tile's Gaussians front to back, tiles in order
  const int* tile_ranges = nullptr;      // tiles x 2: [begin, end) into isect_gaussians
};

class StageRunner {
public:
  virtual ~StageRunner() = default;
  virtual const char* name() const = 0;
  // Projection, SH and tile intersection of `model` (float), seen by `camera`.
  virtual const ForwardStages& forward(const cpu::ModelView<float>& model, const float* opacity_multiplier,
                                       const CameraParams<float>& camera, const StageOptions& options) = 0;
  // Projection and SH backward for the model, multiplier and camera of the last forward (alive).
  virtual const BackwardStages& backward(const ProjectedGradsIn& grads) = 0;
  // Compositing of the last forward()'s (or load_projected()'s) Gaussians and tile lists.
  virtual const CompositeStages& composite(const CompositeOptions& options) = 0;
  // Compositing's backward for the last composite(), from dL/d rgb, alpha, depth (H x W x 3, H x W, H x W;
  // each may be null = zero). The gradients stay on the device for backward_from_composite().
  virtual const CompositeGrads& composite_backward(const float* d_rgb, const float* d_alpha, const float* d_depth) = 0;
  // Projection and SH backward from the last composite_backward()'s gradients, all on the device (the
  // model, multiplier and camera of the last forward(), alive).
  virtual const BackwardStages& backward_from_composite() = 0;
  // Replaces the outputs of forward() by host arrays (then only composite and composite_backward apply).
  virtual void load_projected(const ProjectedIn& in) = 0;
  // The device scan alone (kernels/scan_kernels.hpp), for tests of sizes the scenes do not reach.
  virtual std::vector<int> inclusive_scan(const std::vector<int>& values) = 0;

  // Timing mode (bench/bench_cuda.cpp), off by default: the stages copy none of their outputs to the host
  // (the returned structs keep their last values), and forward() uploads the model only when its arrays
  // (pointers, count, SH size, multiplier) differ from the last upload, so a chain of calls measures the
  // device's work plus the one scalar each forward() reads back. The caller must not change a model's
  // values in place while timing mode is on.
  virtual void set_timing_mode(bool on) = 0;
  // Waits until every stage launched so far has finished (a no-op on the CPU).
  virtual void synchronize() = 0;
};

// The kernels run on the CPU by the emulator (kernels/emulate.hpp).
std::unique_ptr<StageRunner> make_emulated_stages(emulate::Schedule schedule = emulate::Schedule::Forward);

}  // namespace d2gs::render::kernels
