#include "d2gs/render/cpu/composite.hpp"

#include <algorithm>
#include <cstdlib>
#include <string>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/render/cpu/composite_tiles.hpp"

namespace d2gs::render::cpu {

namespace {

struct IsaChoice {
  const TileKernels<float>* kernels = nullptr;
};

#if defined(D2GS_TILE_ISA_X86)
// Whether this CPU runs the code built with -march=x86-64-v3 ("avx2") or -march=x86-64-v4 ("avx512") (after
// __builtin_cpu_init). GCC's __builtin_cpu_supports knows the levels by name. Clang 14's rejects those
// names ("invalid cpu feature string for builtin") and names only some of v3's features, so with clang a
// level is the features that it can ask for: AVX2, FMA, BMI1 and BMI2 on top of v2's POPCNT and SSE4.2
// (the x86 CPUs that have them, Intel from Haswell and AMD from Excavator, also have v3's F16C, LZCNT and
// MOVBE), and for v4 AVX-512 F, BW, CD, DQ and VL on top.
bool cpu_runs_x86_64_v3() {
#if defined(__clang__)
  return __builtin_cpu_supports("popcnt") && __builtin_cpu_supports("sse4.2") && __builtin_cpu_supports("avx2") &&
         __builtin_cpu_supports("fma") && __builtin_cpu_supports("bmi") && __builtin_cpu_supports("bmi2");
#else
  return __builtin_cpu_supports("x86-64-v3");
#endif
}

bool cpu_runs_x86_64_v4() {
#if defined(__clang__)
  return cpu_runs_x86_64_v3() && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
         __builtin_cpu_supports("avx512cd") && __builtin_cpu_supports("avx512dq") && __builtin_cpu_supports("avx512vl");
#else
  return __builtin_cpu_supports("x86-64-v4");
#endif
}
#endif

bool cpu_runs(const std::string& isa) {
  if (isa == "baseline") return true;
#if defined(D2GS_TILE_ISA_X86)
  __builtin_cpu_init();
  if (isa == "avx2") return cpu_runs_x86_64_v3();
  if (isa == "avx512") return cpu_runs_x86_64_v4();
#endif
  return false;
}

const TileKernels<float>* kernels_named(const std::string& isa) {
  if (isa == "baseline") return &baseline::kernels_float();
#if defined(D2GS_TILE_ISA_X86)
  if (isa == "avx2") return &avx2::kernels_float();
  if (isa == "avx512") return &avx512::kernels_float();
#endif
  return nullptr;
}

std::string joined(const std::vector<std::string>& v) {
  std::string out;
  for (const auto& s : v) out += (out.empty() ? "" : ", ") + s;
  return out;
}

IsaChoice& choice() {
  static IsaChoice c = [] {
    IsaChoice r;
    const std::vector<std::string> isas = available_tile_isas();
    std::string pick = isas.back();
    if (const char* env = std::getenv("D2GS_CPU_ISA"); env && *env) {
      if (std::find(isas.begin(), isas.end(), std::string(env)) == isas.end())
        fail("D2GS_CPU_ISA={}: not a level this build and CPU run (available: {})", env, joined(isas));
      pick = env;
    }
    r.kernels = kernels_named(pick);
    return r;
  }();
  return c;
}

}  // namespace

std::vector<std::string> available_tile_isas() {
  std::vector<std::string> out;
  for (const char* isa : {"baseline", "avx2", "avx512"})
    if (kernels_named(isa) && cpu_runs(isa)) out.emplace_back(isa);
  return out;
}

void select_tile_isa(const std::string& name) {
  const auto isas = available_tile_isas();
  if (std::find(isas.begin(), isas.end(), name) == isas.end())
    fail("CPU instruction set '{}' is not available (this build and CPU run: {})", name, joined(isas));
  choice().kernels = kernels_named(name);
}

const TileKernels<float>& tile_kernels_float() { return *choice().kernels; }
std::string selected_tile_isa() { return tile_kernels_float().isa; }
const TileKernels<double>& tile_kernels_double() { return baseline::kernels_double(); }

namespace {

template <typename T>
const TileKernels<T>& kernels_for();
template <>
const TileKernels<float>& kernels_for<float>() {
  return tile_kernels_float();
}
template <>
const TileKernels<double>& kernels_for<double>() {
  return tile_kernels_double();
}

}  // namespace

template <typename T>
void composite_forward(const Binning<T>& bin, const T background[3], bool smooth_cutoff, T* rgb, T* alpha,
                       T* depth, PixelState<T>& state) {
  const std::size_t pixels = static_cast<std::size_t>(bin.width) * bin.height;
  grow(state.final_transmittance, pixels);
  grow(state.n_contrib, pixels);
  const int n_tiles = bin.tiles_x * bin.tiles_y;
  const auto forward_tile = kernels_for<T>().forward;
#pragma omp parallel for schedule(dynamic, 1)
  for (int tile = 0; tile < n_tiles; ++tile)
    forward_tile(bin, tile, background, smooth_cutoff, rgb, alpha, depth, state);
}

template <typename T>
void composite_backward(const Binning<T>& bin, const T background[3], bool smooth_cutoff, bool clamp_pass_through,
                        const PixelState<T>& state, const T* d_rgb, const T* d_alpha, const T* d_depth,
                        std::size_t n, std::vector<T>& isect_grads, ProjectedGrads<T>& out) {
  grow(isect_grads, bin.intersections * kIsectGradStride);
  out.resize(n);
  const int n_tiles = bin.tiles_x * bin.tiles_y;
  T* ig = isect_grads.data();
  const auto backward_tile = kernels_for<T>().backward;
#pragma omp parallel
  {
#pragma omp for schedule(dynamic, 1) nowait
    for (int tile = 0; tile < n_tiles; ++tile)
      backward_tile(bin, tile, background, smooth_cutoff, clamp_pass_through, state, d_rgb, d_alpha, d_depth, ig);
    // Gaussians that were not binned get zero gradients.
#pragma omp for schedule(static)
    for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i) {
      out.mean2d[i * 2] = out.mean2d[i * 2 + 1] = T(0);
      out.conic[i * 3] = out.conic[i * 3 + 1] = out.conic[i * 3 + 2] = T(0);
      out.opacity[i] = out.depth[i] = T(0);
      out.color[i * 3] = out.color[i * 3 + 1] = out.color[i * 3 + 2] = T(0);
    }
    // Per Gaussian: sum of its intersections in tile order.
#pragma omp for schedule(static)
    for (std::ptrdiff_t r = 0; r < static_cast<std::ptrdiff_t>(bin.ranks); ++r) {
      T acc[kIsectGradStride] = {};
      for (int k = bin.rank_isect_offsets[r]; k < bin.rank_isect_offsets[r + 1]; ++k) {
        const T* g = ig + static_cast<std::size_t>(bin.rank_isects[k]) * kIsectGradStride;
        for (int c = 0; c < kIsectGradStride; ++c) acc[c] += g[c];
      }
      const int i = bin.rank_gaussian[r];
      out.mean2d[i * 2] = acc[0];
      out.mean2d[i * 2 + 1] = acc[1];
      out.conic[i * 3] = acc[2];
      out.conic[i * 3 + 1] = acc[3];
      out.conic[i * 3 + 2] = acc[4];
      out.opacity[i] = acc[5];
      out.color[i * 3] = acc[6];
      out.color[i * 3 + 1] = acc[7];
      out.color[i * 3 + 2] = acc[8];
      out.depth[i] = acc[9];
    }
  }
}

template void composite_forward<float>(const Binning<float>&, const float[3], bool, float*, float*, float*,
                                       PixelState<float>&);
template void composite_forward<double>(const Binning<double>&, const double[3], bool, double*, double*,
                                        double*, PixelState<double>&);
template void composite_backward<float>(const Binning<float>&, const float[3], bool, bool, const PixelState<float>&,
                                        const float*, const float*, const float*, std::size_t,
                                        std::vector<float>&, ProjectedGrads<float>&);
template void composite_backward<double>(const Binning<double>&, const double[3], bool, bool,
                                         const PixelState<double>&, const double*, const double*,
                                         const double*, std::size_t, std::vector<double>&,
                                         ProjectedGrads<double>&);

}  // namespace d2gs::render::cpu
