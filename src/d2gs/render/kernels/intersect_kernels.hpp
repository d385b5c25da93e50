#pragma once
// Tile intersection (gsplat's IntersectTile): the tiles of every Gaussian, an inclusive scan of their
// counts into offsets (scan_kernels.hpp), one 64-bit key per (tile, Gaussian) pair = tile << 32 | the
// bits of the positive float depth, a radix sort of the keys (CUB on the GPU, a stable sort in
// emulation), and every tile's range of the sorted pairs. The keys are emitted in Gaussian order and the
// sort is stable, so a tile's list is front to back with equal depths in Gaussian order, as the CPU
// backend's binning (cpu/binning.cpp), whose tile rectangle, and the tiles of it kept
// (raster_math.hpp, for_each_reached_tile), this computes with the same functions.
#include <stdint.h>

#include "d2gs/render/kernels/block.hpp"
#include "d2gs/render/projection_math.hpp"
#include "d2gs/render/raster_math.hpp"

namespace d2gs::render::kernels {

struct TileCountArgs {
  int n = 0, tiles_x = 0, tiles_y = 0, height = 0;
  float alpha_min = 0;  // the compositing cutoff (1/255, or 0.5/255 for the smooth cutoff)
  const float* mean2d = nullptr;
  const float* conic = nullptr;
  const float* opacity = nullptr;
  const int* radii = nullptr;
  int* rects = nullptr;    // N x 4: tiles [x0, x1) x [y0, y1), all 0 when none
  int* counts = nullptr;   // N: tiles of the rectangle kept (for_each_reached_tile)
  int* offsets = nullptr;  // N: the counts again, scanned in place afterwards
};

// The getRect tile rectangle of the original, intersected with the tiles of the alpha box; `reach` the
// test of the tiles of it kept (all of them when the rectangle is empty).
D2GS_HD void tile_rect_and_reach(int i, const TileCountArgs& a, int rect[4], TileReach<float>& reach) {
  rect[0] = rect[1] = rect[2] = rect[3] = 0;
  reach = TileReach<float>{};
  if (a.radii[i] <= 0) return;
  const float mx = a.mean2d[i * 2], my = a.mean2d[i * 2 + 1];
  int r[4], box[4];
  tile_rect(mx, my, a.radii[i], a.tiles_x, a.tiles_y, r);
  if (!alpha_pixel_box(mx, my, a.conic + i * 3, a.opacity[i], a.alpha_min, box)) return;
  const int bx0 = box[0] < 0 ? 0 : box[0] / kTileSize;
  const int bx1 = box[1] < 0 ? 0 : box[1] / kTileSize + 1;
  const int by0 = box[2] < 0 ? 0 : box[2] / kTileSize;
  const int by1 = box[3] < 0 ? 0 : box[3] / kTileSize + 1;
  rect[0] = hd_max(r[0], bx0);
  rect[1] = hd_max(r[1], by0);
  rect[2] = hd_min(r[2], bx1);
  rect[3] = hd_min(r[3], by1);
  if (rect[2] <= rect[0] || rect[3] <= rect[1]) {
    rect[0] = rect[1] = rect[2] = rect[3] = 0;
    return;
  }
  reach = tile_reach_setup(mx, my, a.conic + i * 3, 2.0f * hd_log(a.opacity[i] / a.alpha_min), box, a.height);
}

D2GS_HD void tile_count_thread(int i, const TileCountArgs& a) {
  int* rect = a.rects + i * 4;
  TileReach<float> reach;
  tile_rect_and_reach(i, a, rect, reach);
  const int count = for_each_reached_tile(reach, rect, [](int, int) {});
  a.counts[i] = count;
  a.offsets[i] = count;
}

using TileCountKernel = PerItemKernel<TileCountArgs, tile_count_thread>;

struct EmitKeysArgs {
  int n = 0;
  TileCountArgs tiles;           // the tile counts' inputs (rects computed again, the same)
  const int* offsets = nullptr;  // inclusive scan of the counts
  const float* depth = nullptr;
  uint64_t* keys = nullptr;      // M: tile << 32 | depth bits
  int32_t* gaussians = nullptr;  // M: Gaussian id
};

D2GS_HD uint64_t intersection_key(int tile, float depth) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(tile)) << 32) | float_bits(depth);
}

D2GS_HD void emit_keys_thread(int i, const EmitKeysArgs& a) {
  int rect[4];
  TileReach<float> reach;
  tile_rect_and_reach(i, a.tiles, rect, reach);
  int k = i > 0 ? a.offsets[i - 1] : 0;
  const int tiles_x = a.tiles.tiles_x;
  const float depth = a.depth[i];
  for_each_reached_tile(reach, rect, [&](int tx, int ty) {
    a.keys[k] = intersection_key(ty * tiles_x + tx, depth);
    a.gaussians[k] = i;
    ++k;
  });
}

using EmitKeysKernel = PerItemKernel<EmitKeysArgs, emit_keys_thread>;

struct TileRangesArgs {
  int m = 0;                        // intersections
  const uint64_t* keys = nullptr;   // sorted
  int* ranges = nullptr;            // tiles x 2: [begin, end) of each tile's sorted pairs; zeroed before
};

D2GS_HD void tile_ranges_thread(int j, const TileRangesArgs& a) {
  const int tile = static_cast<int>(a.keys[j] >> 32);
  if (j == 0) {
    a.ranges[tile * 2] = 0;
  } else {
    const int prev = static_cast<int>(a.keys[j - 1] >> 32);
    if (prev != tile) {
      a.ranges[prev * 2 + 1] = j;
      a.ranges[tile * 2] = j;
    }
  }
  if (j == a.m - 1) a.ranges[tile * 2 + 1] = a.m;
}

struct TileRangesKernel {
  struct Shared {};
  template <class Block>
  D2GS_HD static void run(Block& b, Shared&, const TileRangesArgs& a) {
    b.threads([&](const Thread& t) {
      const int j = t.global_x();
      if (j < a.m) tile_ranges_thread(j, a);
    });
  }
};

}  // namespace d2gs::render::kernels
