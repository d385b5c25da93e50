#include "d2gs/render/cpu/binning.hpp"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <optional>

#include "d2gs/core/stage_profile.hpp"
#include "d2gs/render/raster_math.hpp"

namespace d2gs::render::cpu {

namespace {

std::uint32_t depth_key(float depth) {
  std::uint32_t bits;
  std::memcpy(&bits, &depth, sizeof bits);
  return bits;  // depth > 0.2 > 0: the IEEE bit pattern orders like the value
}

// Stable LSD radix sort of (keys, ids) by keys, 8 bits per pass; passes whose digit is constant are
// skipped.
void radix_sort(std::vector<std::uint32_t>& keys, std::vector<int>& ids, std::vector<std::uint32_t>& keys_tmp,
                std::vector<int>& ids_tmp, std::size_t n) {
  std::array<std::array<std::size_t, 256>, 4> hist{};
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t k = keys[i];
    ++hist[0][k & 255u];
    ++hist[1][(k >> 8) & 255u];
    ++hist[2][(k >> 16) & 255u];
    ++hist[3][k >> 24];
  }
  grow(keys_tmp, n);
  grow(ids_tmp, n);
  std::uint32_t* src_k = keys.data();
  int* src_i = ids.data();
  std::uint32_t* dst_k = keys_tmp.data();
  int* dst_i = ids_tmp.data();
  for (int pass = 0; pass < 4; ++pass) {
    auto& h = hist[pass];
    if (std::any_of(h.begin(), h.end(), [n](std::size_t c) { return c == n; })) continue;
    std::size_t sum = 0;
    for (auto& c : h) {
      const std::size_t count = c;
      c = sum;
      sum += count;
    }
    const int shift = pass * 8;
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t pos = h[(src_k[i] >> shift) & 255u]++;
      dst_k[pos] = src_k[i];
      dst_i[pos] = src_i[i];
    }
    std::swap(src_k, dst_k);
    std::swap(src_i, dst_i);
  }
  if (src_k != keys.data()) {
    std::memcpy(keys.data(), src_k, n * sizeof(std::uint32_t));
    std::memcpy(ids.data(), src_i, n * sizeof(int));
  }
}

}  // namespace

template <typename T>
void bin_gaussians(const Projected<T>& proj, int width, int height, double alpha_min, Binning<T>& out,
                   bool cull_tiles) {
  const std::size_t n = proj.count;
  out.width = width;
  out.height = height;
  out.tiles_x = (width + kTileSize - 1) / kTileSize;
  out.tiles_y = (height + kTileSize - 1) / kTileSize;
  const int tiles_x = out.tiles_x, tiles_y = out.tiles_y;
  const std::size_t n_tiles = static_cast<std::size_t>(tiles_x) * tiles_y;
  grow(out.rect, n * 4);
  grow(out.box, n * 4);
  grow(out.reach, n);
  grow(out.rect_offsets, n + 1);
  grow(out.tile_count, n);
  grow(out.keys, n);
  grow(out.ids, n);

  // Its parts' wall time (core/stage_profile.hpp), each scope ending where the next begins.
  std::optional<profile::Scope> ps(std::in_place, "render: binning / rectangles");
  // 1. Tile rectangle of every Gaussian (empty when culled or too faint to reach the cutoff).
  const T amin = T(alpha_min);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i) {
    int* rect = &out.rect[i * 4];
    rect[0] = rect[1] = rect[2] = rect[3] = 0;
    out.rect_offsets[i + 1] = 0;
    if (proj.radii[i] <= 0) continue;
    const T mx = proj.mean2d[i * 2], my = proj.mean2d[i * 2 + 1];
    int r[4];
    int* box = &out.box[i * 4];
    tile_rect(mx, my, proj.radii[i], tiles_x, tiles_y, r);
    if (!alpha_pixel_box(mx, my, &proj.conic[i * 3], proj.opacity[i], amin, box)) continue;
    out.reach[i] = T(2) * hd_log(proj.opacity[i] / amin);
    // Tiles of the pixel box (pixel p lies in tile p / 16); empty ranges when the box is off-image.
    const int bx0 = box[0] < 0 ? 0 : box[0] / kTileSize;
    const int bx1 = box[1] < 0 ? 0 : box[1] / kTileSize + 1;
    const int by0 = box[2] < 0 ? 0 : box[2] / kTileSize;
    const int by1 = box[3] < 0 ? 0 : box[3] / kTileSize + 1;
    rect[0] = std::max(r[0], bx0);
    rect[1] = std::max(r[1], by0);
    rect[2] = std::min(r[2], bx1);
    rect[3] = std::min(r[3], by1);
    if (rect[2] <= rect[0] || rect[3] <= rect[1]) rect[0] = rect[1] = rect[2] = rect[3] = 0;
    out.rect_offsets[i + 1] = (rect[2] - rect[0]) * (rect[3] - rect[1]);
  }
  out.rect_offsets[0] = 0;
  {
    std::int64_t total = 0;  // each area fits an int (tiles_x·tiles_y), their sum may not: checked before use
    for (std::size_t i = 0; i < n; ++i) {
      total += out.rect_offsets[i + 1];
      out.rect_offsets[i + 1] = static_cast<int>(total);
    }
    check_intersection_count(total, width, height);
  }
  grow(out.rect_tiles, static_cast<std::size_t>(out.rect_offsets[n]));

  ps.emplace("render: binning / tiles reached");
  // The tiles of each rectangle that the tile loops may visit (raster_math.hpp, tile_reach_columns), in
  // row-major order, at the start of the rectangle's slot of rect_tiles.
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i) {
    const int* rect = &out.rect[i * 4];
    int* tiles = &out.rect_tiles[out.rect_offsets[i]];
    int count = 0;
    if (out.rect_offsets[i + 1] > out.rect_offsets[i]) {
      const TileReach<T> reach =
          cull_tiles ? tile_reach_setup(proj.mean2d[i * 2], proj.mean2d[i * 2 + 1], &proj.conic[i * 3], out.reach[i],
                                        &out.box[i * 4], height)
                     : TileReach<T>{};
      count = for_each_reached_tile(reach, rect, [&](int tx, int ty) { tiles[count++] = ty * tiles_x + tx; });
    }
    out.tile_count[i] = count;
  }

  ps.emplace("render: binning / depth sort");
  // 2. Candidates in index order, then a stable sort by depth.
  std::size_t ranks = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if (out.tile_count[i] > 0) {
      out.keys[ranks] = depth_key(static_cast<float>(proj.depth[i]));
      out.ids[ranks] = static_cast<int>(i);
      ++ranks;
    }
  }
  radix_sort(out.keys, out.ids, out.keys_tmp, out.ids_tmp, ranks);
  out.ranks = ranks;

  ps.emplace("render: binning / splats");
  // 3. Splats in depth order and the per-rank intersection offsets.
  grow(out.rank_gaussian, ranks);
  grow(out.splats, ranks);
  grow(out.rank_isect_offsets, ranks + 1);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t r = 0; r < static_cast<std::ptrdiff_t>(ranks); ++r) {
    const int i = out.ids[r];
    out.rank_gaussian[r] = i;
    Splat<T>& s = out.splats[r];
    s.mx = proj.mean2d[i * 2];
    s.my = proj.mean2d[i * 2 + 1];
    s.qa = proj.conic[i * 3];
    s.qb = proj.conic[i * 3 + 1];
    s.qc = proj.conic[i * 3 + 2];
    s.opacity = proj.opacity[i];
    s.r = proj.color[i * 3];
    s.g = proj.color[i * 3 + 1];
    s.b = proj.color[i * 3 + 2];
    s.z = proj.depth[i];
    const int* box = &out.box[i * 4];  // alpha_pixel_box's, set (as reach) for every candidate
    s.x0 = box[0];
    s.x1 = box[1];
    s.y0 = box[2];
    s.y1 = box[3];
    s.reach = out.reach[i];  // 2 ln(opacity / alpha_min)
    s.inv_qa = T(1) / s.qa;
    out.rank_isect_offsets[r + 1] = out.tile_count[i];
  }
  out.rank_isect_offsets[0] = 0;
  for (std::size_t r = 0; r < ranks; ++r) out.rank_isect_offsets[r + 1] += out.rank_isect_offsets[r];
  const std::size_t m = static_cast<std::size_t>(out.rank_isect_offsets[ranks]);
  out.intersections = m;
  grow(out.rank_isects, m);
  grow(out.isect_rank, m);
  grow(out.tile_offsets, n_tiles + 1);

  ps.emplace("render: binning / tile counts");
  // 4. Tile lists: chunk c of the ranks counts its tiles, offsets are tile-major then chunk-major, and
  // each chunk fills its slots in rank order. Any chunking gives the same layout.
  const int chunks = std::max(1, std::min<int>(omp_get_max_threads(), static_cast<int>(ranks / 1024) + 1));
  grow(out.chunk_counts, static_cast<std::size_t>(chunks) * n_tiles);
  const auto chunk_begin = [&](int c) { return ranks * static_cast<std::size_t>(c) / chunks; };
#pragma omp parallel for schedule(static, 1) num_threads(chunks)
  for (int c = 0; c < chunks; ++c) {
    int* counts = &out.chunk_counts[static_cast<std::size_t>(c) * n_tiles];
    std::fill(counts, counts + n_tiles, 0);
    for (std::size_t r = chunk_begin(c); r < chunk_begin(c + 1); ++r) {
      const int i = out.ids[r];
      const int* tiles = &out.rect_tiles[out.rect_offsets[i]];
      for (int j = 0; j < out.tile_count[i]; ++j) ++counts[tiles[j]];
    }
  }
  int offset = 0;
  for (std::size_t t = 0; t < n_tiles; ++t) {
    out.tile_offsets[t] = offset;
    for (int c = 0; c < chunks; ++c) {
      int& count = out.chunk_counts[static_cast<std::size_t>(c) * n_tiles + t];
      const int k = count;
      count = offset;  // becomes the chunk's cursor in this tile
      offset += k;
    }
  }
  out.tile_offsets[n_tiles] = offset;
  ps.emplace("render: binning / tile lists");
#pragma omp parallel for schedule(static, 1) num_threads(chunks)
  for (int c = 0; c < chunks; ++c) {
    int* cursor = &out.chunk_counts[static_cast<std::size_t>(c) * n_tiles];
    for (std::size_t r = chunk_begin(c); r < chunk_begin(c + 1); ++r) {
      const int i = out.ids[r];
      const int* tiles = &out.rect_tiles[out.rect_offsets[i]];
      int k = out.rank_isect_offsets[r];
      for (int j = 0; j < out.tile_count[i]; ++j) {
        const int pos = cursor[tiles[j]]++;
        out.isect_rank[pos] = static_cast<int>(r);
        out.rank_isects[k++] = pos;
      }
    }
  }
}

template void bin_gaussians<float>(const Projected<float>&, int, int, double, Binning<float>&, bool);
template void bin_gaussians<double>(const Projected<double>&, int, int, double, Binning<double>&, bool);

}  // namespace d2gs::render::cpu
