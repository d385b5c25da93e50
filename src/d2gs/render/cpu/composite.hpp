#pragma once
// Stage 4: alpha compositing per 16x16 tile (raster_math.hpp), forward and backward.
//
// Parallel over tiles (OpenMP); the per-tile loops are in composite_tiles.ipp, built once per x86-64
// level and picked at run time (composite_tiles.hpp).
//
// Backward: per tile, back to front, each intersection's partial gradients (mean2d 2, conic 3,
// opacity, colour 3, depth) are summed over the tile's pixels in a fixed order and written to an
// intersection-indexed buffer; then every Gaussian sums its intersections in tile order. No atomics,
// so results are bit-identical whatever the number of threads.
#include "d2gs/render/cpu/composite_tiles.hpp"

namespace d2gs::render::cpu {

// rgb: H x W x 3 (interleaved, not clamped; background added with the final transmittance),
// alpha = 1 - T_final, depth = sum_i alpha_i T_i z_i. Any of the three outputs may be null.
template <typename T>
void composite_forward(const Binning<T>& bin, const T background[3], bool smooth_cutoff, T* rgb, T* alpha,
                       T* depth, PixelState<T>& state);

// Gradients w.r.t. the Projected quantities of the n Gaussians (zero for those not binned) from the
// gradients w.r.t. rgb, alpha and depth (each may be null = zero). clamp_pass_through: the gradient
// through alpha = min(0.99, o G) as if unclamped (the original rasterizer's rule; raster_math.hpp).
template <typename T>
void composite_backward(const Binning<T>& bin, const T background[3], bool smooth_cutoff, bool clamp_pass_through,
                        const PixelState<T>& state, const T* d_rgb, const T* d_alpha, const T* d_depth,
                        std::size_t n, std::vector<T>& isect_grads, ProjectedGrads<T>& out);

}  // namespace d2gs::render::cpu
