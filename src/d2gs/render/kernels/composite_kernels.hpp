#pragma once
// Alpha compositing, forward and backward, in the field's shape (Inria's renderCUDA, gsplat's
// rasterize_to_pixels): one block per 16 x 16 tile, one thread per pixel (thread t: column t % 16, row
// t / 16, so a warp is two pixel rows), the tile's Gaussians [tile_ranges) loaded into shared memory in
// batches of one per thread, a barrier before and after every batch. The per-pixel arithmetic is
// composite_math.hpp's, the CPU tile loops' lane arithmetic, so every per-pixel value is the CPU's bit for
// bit (for the CPU's choice of fused multiply-adds: template parameter Fused).
//
// Forward: front to back; a pixel stops when T would fall below 1e-4 (hard cutoff), the block when all
// its pixels have (__syncthreads_count). Writes rgb (over the background), alpha = 1 - T, depth, and for
// the backward the final T and the pixel's last contributor.
//
// Backward: the tile's largest last contributor (a warp max by shuffles, the warps' through shared
// memory) bounds the list; batches are loaded back to front and each pixel replays the forward from its
// final T. For every Gaussian of the batch, the pixels' terms (SplatGrad: ten sums) are reduced over each
// warp where some pixel composited it (a warp vote) by shfl_down, and lane 0 adds the warp's total to the
// Gaussian's gradients with one atomic per non-zero value. Sums over pixels and tiles thus run in another order than the CPU's (its lane sums and
// its per-Gaussian sum over intersections in tile order), and on the GPU in no fixed order at all.
#include "d2gs/render/composite_math.hpp"
#include "d2gs/render/kernels/block.hpp"

namespace d2gs::render::kernels {

inline constexpr int kCompositeBlock = kTileSize * kTileSize;  // threads per block, Gaussians per batch

struct CompositeFwdArgs {
  int width = 0, height = 0, tiles_x = 0;
  const float* mean2d = nullptr;   // N x 2
  const float* conic = nullptr;    // N x 3
  const float* opacity = nullptr;  // N
  const float* color = nullptr;    // N x 3
  const float* depth = nullptr;    // N
  const int* isect_gaussians = nullptr;  // M: the sorted intersections' Gaussians
  const int* tile_ranges = nullptr;      // tiles x 2: [begin, end) into isect_gaussians
  float background[3] = {0, 0, 0};
  float* rgb = nullptr;          // H x W x 3
  float* alpha = nullptr;        // H x W
  float* out_depth = nullptr;    // H x W
  float* final_t = nullptr;      // H x W
  int* n_contrib = nullptr;      // H x W
};

// Gaussian g's compositing parameters.
D2GS_HD SplatParams load_splat(int g, const float* mean2d, const float* conic, const float* opacity,
                               const float* color, const float* depth) {
  SplatParams s;
  s.mx = mean2d[g * 2];
  s.my = mean2d[g * 2 + 1];
  s.qa = conic[g * 3];
  s.qb = conic[g * 3 + 1];
  s.qc = conic[g * 3 + 2];
  s.opacity = opacity[g];
  s.r = color[g * 3];
  s.g = color[g * 3 + 1];
  s.b = color[g * 3 + 2];
  s.z = depth[g];
  return s;
}

// The pixel of thread t in tile t.block_x (pixel coordinates are the original's: centres at integers).
struct TilePixel {
  int x, y;
  bool inside;
};
D2GS_HD TilePixel tile_pixel(const Thread& t, int tiles_x, int width, int height) {
  TilePixel p;
  p.x = (t.block_x % tiles_x) * kTileSize + t.linear() % kTileSize;
  p.y = (t.block_x / tiles_x) * kTileSize + t.linear() / kTileSize;
  p.inside = p.x < width && p.y < height;
  return p;
}

template <bool Smooth, bool Fused>
struct CompositeFwdKernel {
  struct Shared {
    SplatParams batch[kCompositeBlock];
  };
  template <class Block>
  D2GS_HD static void run(Block& b, Shared& sh, const CompositeFwdArgs& a) {
    auto px = b.template reg<PixelForward>();
    auto done = b.template reg<int>();
    b.threads([&](const Thread& t) {
      pixel_forward_init(px[t], tile_pixel(t, a.tiles_x, a.width, a.height).inside);
      done[t] = px[t].done;
    });
    const int tile = b.block_idx().x;
    const int begin = a.tile_ranges[tile * 2], end = a.tile_ranges[tile * 2 + 1];
    for (int start = begin; start < end; start += kCompositeBlock) {
      // The barrier before the batch is overwritten; it also counts the pixels done.
      if (b.sync_count(done) == kCompositeBlock) break;
      b.threads([&](const Thread& t) {
        const int j = start + t.linear();
        if (j < end)
          sh.batch[t.linear()] = load_splat(a.isect_gaussians[j], a.mean2d, a.conic, a.opacity, a.color, a.depth);
      });
      b.sync();
      const int count = end - start < kCompositeBlock ? end - start : kCompositeBlock;
      b.threads([&](const Thread& t) {
        const TilePixel p = tile_pixel(t, a.tiles_x, a.width, a.height);
        PixelForward& s = px[t];
        for (int k = 0; k < count && !s.done; ++k)
          pixel_forward_step<Smooth, Fused>(s, sh.batch[k], float(p.x), float(p.y), start - begin + k);
        done[t] = s.done;
      });
    }
    b.threads([&](const Thread& t) {
      const TilePixel p = tile_pixel(t, a.tiles_x, a.width, a.height);
      if (!p.inside) return;
      const int i = p.y * a.width + p.x;
      float rgb[3], alpha, depth;
      pixel_forward_outputs(px[t], a.background, rgb, alpha, depth);
      if (a.rgb) {
        a.rgb[i * 3] = rgb[0];
        a.rgb[i * 3 + 1] = rgb[1];
        a.rgb[i * 3 + 2] = rgb[2];
      }
      if (a.alpha) a.alpha[i] = alpha;
      if (a.out_depth) a.out_depth[i] = depth;
      a.final_t[i] = px[t].t;
      a.n_contrib[i] = px[t].last;
    });
  }
};

struct CompositeBwdArgs {
  int width = 0, height = 0, tiles_x = 0;
  const float* mean2d = nullptr;
  const float* conic = nullptr;
  const float* opacity = nullptr;
  const float* color = nullptr;
  const float* depth = nullptr;
  const int* isect_gaussians = nullptr;
  const int* tile_ranges = nullptr;
  float background[3] = {0, 0, 0};
  bool clamp_pass_through = false;
  const float* final_t = nullptr;    // H x W, of the forward
  const int* n_contrib = nullptr;    // H x W, of the forward
  const float* d_rgb = nullptr;      // H x W x 3, or null (= zero)
  const float* d_alpha = nullptr;    // H x W, or null
  const float* d_depth = nullptr;    // H x W, or null
  // N-sized, zeroed before the launch; the kernel adds.
  float* d_mean2d = nullptr;   // N x 2
  float* d_conic = nullptr;    // N x 3
  float* d_opacity = nullptr;  // N
  float* d_color = nullptr;    // N x 3
  float* d_splat_depth = nullptr;  // N
};

template <bool Smooth, bool Fused>
struct CompositeBwdKernel {
  struct Shared {
    SplatParams batch[kCompositeBlock];
    int ids[kCompositeBlock];
    int warp_max[kCompositeBlock / kWarpSize];
  };
  template <class Block>
  D2GS_HD static void run(Block& b, Shared& sh, const CompositeBwdArgs& a) {
    auto px = b.template reg<PixelBackward>();
    auto m = b.template reg<int>();
    auto other = b.template reg<int>();
    b.threads([&](const Thread& t) {
      const TilePixel p = tile_pixel(t, a.tiles_x, a.width, a.height);
      if (!p.inside) {
        const float zero[3] = {0, 0, 0};
        pixel_backward_init(px[t], 0.0f, 0, nullptr, 0.0f, 0.0f, zero);
      } else {
        const int i = p.y * a.width + p.x;
        pixel_backward_init(px[t], a.final_t[i], a.n_contrib[i], a.d_rgb ? a.d_rgb + i * 3 : nullptr,
                            a.d_alpha ? a.d_alpha[i] : 0.0f, a.d_depth ? a.d_depth[i] : 0.0f, a.background);
      }
      m[t] = px[t].last;
    });
    // The tile's largest last contributor: a warp max by butterfly shuffles, then the warps'.
    for (int d = kWarpSize / 2; d > 0; d /= 2) {
      b.shfl_xor(other, m, d);
      b.threads([&](const Thread& t) { m[t] = other[t] > m[t] ? other[t] : m[t]; });
    }
    b.threads([&](const Thread& t) {
      if (t.lane() == 0) sh.warp_max[t.warp()] = m[t];
    });
    b.sync();
    int tile_max = 0;
    for (int w = 0; w < kCompositeBlock / kWarpSize; ++w) tile_max = sh.warp_max[w] > tile_max ? sh.warp_max[w] : tile_max;
    const int begin = a.tile_ranges[b.block_idx().x * 2];

    auto g = b.template reg<SplatGrad>();
    auto g_other = b.template reg<SplatGrad>();
    auto valid = b.template reg<int>();
    auto active = b.template reg<int>();
    for (int hi = tile_max; hi > 0; hi -= kCompositeBlock) {
      const int lo = hi > kCompositeBlock ? hi - kCompositeBlock : 0;
      b.sync();  // the previous batch is no longer read
      b.threads([&](const Thread& t) {
        const int k = t.linear();
        if (lo + k >= hi) return;
        const int id = a.isect_gaussians[begin + lo + k];
        sh.ids[k] = id;
        sh.batch[k] = load_splat(id, a.mean2d, a.conic, a.opacity, a.color, a.depth);
      });
      b.sync();
      for (int jl = hi - 1; jl >= lo; --jl) {
        const int k = jl - lo;
        b.threads([&](const Thread& t) {
          const TilePixel p = tile_pixel(t, a.tiles_x, a.width, a.height);
          splat_grad_zero(g[t]);
          valid[t] = pixel_backward_step<Smooth, Fused>(px[t], sh.batch[k], float(p.x), float(p.y), jl,
                                                        a.clamp_pass_through, g[t]);
        });
        // Warp sum (lane 0 ends with the total), in the warps where some pixel composited the Gaussian.
        b.warp_any(active, valid);
        for (int d = kWarpSize / 2; d > 0; d /= 2) {
          b.shfl_down_if(active, g_other, g, d);
          b.threads([&](const Thread& t) {
            if (active[t]) splat_grad_add(g[t], g_other[t]);
          });
        }
        b.threads([&](const Thread& t) {
          if (t.lane() != 0 || !active[t]) return;
          float v[10];
          splat_grad_finish(g[t], sh.batch[k], v);
          const int id = sh.ids[k];
          float* out[10] = {a.d_mean2d + id * 2,     a.d_mean2d + id * 2 + 1, a.d_conic + id * 3,
                            a.d_conic + id * 3 + 1,  a.d_conic + id * 3 + 2, a.d_opacity + id,
                            a.d_color + id * 3,      a.d_color + id * 3 + 1, a.d_color + id * 3 + 2,
                            a.d_splat_depth + id};
          for (int c = 0; c < 10; ++c)
            if (v[c] != 0.0f) b.atomic_add(out[c], v[c]);
        });
      }
    }
  }
};

}  // namespace d2gs::render::kernels
