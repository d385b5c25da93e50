#pragma once
// The per-tile loops of compositing (stage 4), compiled once per x86-64 level and chosen at run time.
//
// composite.cpp runs these over the tiles (OpenMP) and does everything else of the stage. The loops
// themselves live in composite_tiles.ipp, which composite_tiles_{baseline,avx2,avx512}.cpp compile with
// -march=x86-64 / x86-64-v3 / x86-64-v4, each into its own namespace (simd_math.hpp). The widest
// level the CPU supports is used unless the environment variable D2GS_CPU_ISA names another
// (baseline, avx2, avx512): results differ between levels only by float rounding (lane width, fused
// multiply-add), and are bit-identical from run to run and for any thread count at one level.
#include <string>
#include <vector>

#include "d2gs/render/cpu/types.hpp"

namespace d2gs::render::cpu {

template <typename T>
struct TileKernels {
  const char* isa = "";
  // One tile of the forward pass: writes the tile's pixels of rgb/alpha/depth (each may be null) and of
  // the per-pixel state.
  void (*forward)(const Binning<T>& bin, int tile, const T background[3], bool smooth_cutoff, T* rgb, T* alpha,
                  T* depth, PixelState<T>& state) = nullptr;
  // One tile of the backward pass: writes kIsectGradStride partial gradients for each of the tile's
  // intersections (zero past the tile's last contributor).
  void (*backward)(const Binning<T>& bin, int tile, const T background[3], bool smooth_cutoff,
                   bool clamp_pass_through, const PixelState<T>& state, const T* d_rgb, const T* d_alpha, const T* d_depth,
                   T* isect_grads) = nullptr;
};

inline constexpr int kIsectGradStride = 10;  // mean2d(2) conic(3) opacity colour(3) depth

// The kernels in use: the widest level this CPU runs (or D2GS_CPU_ISA's choice), decided once.
// Double precision (gradient checks) always runs the baseline build.
const TileKernels<float>& tile_kernels_float();
const TileKernels<double>& tile_kernels_double();

// Levels compiled into this build that this CPU can run, narrowest first ("baseline", "avx2", "avx512").
std::vector<std::string> available_tile_isas();
// Selects a level by name for the rest of the process (benchmarks and tests comparing levels); throws
// d2gs::Error when the level is not compiled in or the CPU cannot run it.
void select_tile_isa(const std::string& name);
// The level the float tile loops use now ("baseline", "avx2" or "avx512"). Runs at different levels round
// differently, so a training run records it (config.json, results.json) beside its seed.
std::string selected_tile_isa();

// Per level, defined in composite_tiles_<level>.cpp.
namespace baseline {
const TileKernels<float>& kernels_float();
const TileKernels<double>& kernels_double();
}  // namespace baseline
namespace avx2 {
const TileKernels<float>& kernels_float();
}
namespace avx512 {
const TileKernels<float>& kernels_float();
}

}  // namespace d2gs::render::cpu
