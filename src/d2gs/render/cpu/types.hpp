#pragma once
// Data passed between the CPU stages (projection -> SH -> binning -> compositing and back). Every
// stage is a template on the scalar type, instantiated for float (rendering) and double (the
// finite-difference checks). All vectors are owned by the caller's workspace and only grow.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/render/projection_math.hpp"

namespace d2gs::render::cpu {

// The tile lists index (Gaussian, tile) pairs with 32-bit ints (both backends). A frame that needs more is
// refused with this error instead of overflowing them: its Gaussians are far too large for the image.
inline constexpr std::int64_t kMaxIntersections = 0x7fffffff;
inline void check_intersection_count(std::int64_t pairs, int width, int height) {
  if (pairs > kMaxIntersections)
    fail("render: the Gaussians cover {} (Gaussian, tile) pairs of the {}x{} image, more than the {} the tile "
         "lists can index (a model of huge or far too many overlapping Gaussians; check its scales, or render smaller)",
         pairs, width, height, kMaxIntersections);
}

// Read-only view of a model's parameters (layout of d2gs::Gaussians; sh_rest has
// (model_sh_degree+1)^2-1 coefficients per Gaussian, RGB innermost).
template <typename T>
struct ModelView {
  std::size_t count = 0;
  int sh_degree = 0;  // degree sh_rest is laid out for
  const T* means = nullptr;
  const T* log_scales = nullptr;
  const T* quats = nullptr;
  const T* opacity_logits = nullptr;
  const T* sh_dc = nullptr;
  const T* sh_rest = nullptr;
  int sh_rest_count() const { return (sh_degree + 1) * (sh_degree + 1) - 1; }
};

// Writable gradient arrays of the same layout.
template <typename T>
struct ModelGradView {
  T* means = nullptr;
  T* log_scales = nullptr;
  T* quats = nullptr;
  T* opacity_logits = nullptr;
  T* sh_dc = nullptr;
  T* sh_rest = nullptr;
};

template <typename T>
void grow(std::vector<T>& v, std::size_t n) {
  if (v.size() < n) v.resize(n);
}

// Per-Gaussian outputs of projection and SH (the inputs of compositing). Arrays hold >= N entries.
template <typename T>
struct Projected {
  std::size_t count = 0;
  std::vector<T> mean2d;      // N x 2, original pixel frame (pixel centres at integers)
  std::vector<T> conic;       // N x 3 (Q00, Q01, Q11) of the inverse 2D covariance
  std::vector<T> depth;       // N, view-space z
  std::vector<T> opacity;     // N, sigmoid(logit) * multiplier
  std::vector<int> radii;     // N, 0 = culled
  std::vector<T> color;       // N x 3, SH colour after the clamp
  std::vector<std::uint8_t> color_clamped;  // N x 3
  // What project_backward needs of the forward (valid where radii > 0): the projection's intermediate
  // values and sigmoid(logit), so that the backward does not compute them again.
  std::vector<ProjectionState<T>> state;  // N
  std::vector<T> opacity_sigmoid;         // N
  void resize(std::size_t n) {
    count = n;
    grow(mean2d, n * 2);
    grow(conic, n * 3);
    grow(depth, n);
    grow(opacity, n);
    grow(radii, n);
    grow(color, n * 3);
    grow(color_clamped, n * 3);
    grow(state, n);
    grow(opacity_sigmoid, n);
  }
};

// Gradients w.r.t. the Projected quantities.
template <typename T>
struct ProjectedGrads {
  std::vector<T> mean2d, conic, depth, opacity, color;
  void resize(std::size_t n) {
    grow(mean2d, n * 2);
    grow(conic, n * 3);
    grow(depth, n);
    grow(opacity, n);
    grow(color, n * 3);
  }
};

// What a tile's inner loop needs of one Gaussian, packed in depth order (one cache line in float).
template <typename T>
struct alignas(64) Splat {
  T mx, my, qa, qb, qc, opacity, r, g, b, z;
  int x0, x1, y0, y1;  // inclusive pixel box outside which alpha < the cutoff (raster_math.hpp)
  // alpha >= the cutoff needs d^T Q d <= reach = 2 ln(opacity / cutoff); inv_qa = 1 / Q00. The tile
  // loops use them to bound every pixel row to the ellipse's own x-extent (alpha_row_span).
  T reach, inv_qa;
};

// Tile lists: the intersections of every tile, front to back, and for every Gaussian its
// intersections in tile order (for the deterministic gradient reduction).
template <typename T>
struct Binning {
  int width = 0, height = 0, tiles_x = 0, tiles_y = 0;
  std::size_t ranks = 0;          // Gaussians with at least one intersection
  std::size_t intersections = 0;  // M
  std::vector<std::uint32_t> keys, keys_tmp;
  std::vector<int> ids, ids_tmp;  // candidate Gaussian ids (sorted by depth into ids)
  std::vector<int> rect;          // per Gaussian: tile range x0 y0 x1 y1 (exclusive ends) after culling
  std::vector<int> box;           // per Gaussian with a rectangle: alpha_pixel_box (x0 x1 y0 y1, inclusive)
  std::vector<T> reach;           // per Gaussian with a rectangle: 2 ln(opacity / alpha_min)
  std::vector<int> rect_offsets;  // N + 1: prefix sums of the rectangles' areas (slots in rect_tiles)
  std::vector<int> rect_tiles;    // per Gaussian, at rect_offsets[i]: its tile_count[i] kept tiles (ids)
  std::vector<int> tile_count;    // N: tiles kept of the rectangle (tile_reach_columns) = its intersections
  std::vector<int> rank_gaussian;        // R: Gaussian id of depth rank r
  std::vector<Splat<T>> splats;          // R
  std::vector<int> rank_isect_offsets;   // R + 1
  std::vector<int> rank_isects;          // M: intersection ids of rank r, tile order
  std::vector<int> tile_offsets;         // tiles + 1
  std::vector<int> isect_rank;           // M: rank of each intersection, tiles in order, front to back
  std::vector<int> chunk_counts;         // chunks x tiles
};

// Per-pixel state the backward pass needs from the forward pass.
template <typename T>
struct PixelState {
  std::vector<T> final_transmittance;  // H x W
  std::vector<int> n_contrib;          // H x W: 1 + index (within the tile list) of the last composited
  std::vector<int> tile_max_contrib;   // tiles
};

}  // namespace d2gs::render::cpu
