#pragma once
// Stage 3: tile binning and depth ordering.
//
// A Gaussian with radius > 0 touches the tiles of the original's getRect rectangle, intersected with
// the tiles of its alpha box (the pixels where opacity * exp(power) can reach the alpha cutoff; see
// raster_math.hpp). The second restriction only drops (tile, Gaussian) pairs in which no pixel can
// composite the Gaussian, so results are those of the original; it saves work for faint Gaussians.
// Of that rectangle only the tiles that the tile loops may visit are kept (raster_math.hpp,
// tile_reach_columns: an elongated ellipse misses many tiles of its bounding rectangle); the others would
// composite nothing and receive zero gradients, so dropping them changes no result, only the tile lists
// and the number of intersections.
// Ordering: one stable LSD radix sort of the candidate Gaussians by the bits of their (positive) float
// view depth, ties in Gaussian index order, as the original's stable sort of (tile, depth) keys.
// Tile lists are then filled in that order (chunked over threads with per-chunk tile counts), so every
// list is front to back, and the layout does not depend on the number of threads.
#include "d2gs/render/cpu/types.hpp"

namespace d2gs::render::cpu {

// alpha_min: the alpha cutoff of the compositing mode (1/255, or 0.5/255 for the smooth cutoff).
// cull_tiles = false keeps every tile of the rectangles (tests: results must not change).
template <typename T>
void bin_gaussians(const Projected<T>& proj, int width, int height, double alpha_min, Binning<T>& out,
                   bool cull_tiles = true);

}  // namespace d2gs::render::cpu
