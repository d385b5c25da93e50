#include "d2gs/render/cpu/composite.hpp"

#include <algorithm>
#include <cstring>

#include "d2gs/render/cpu/simd_math.hpp"
#include "d2gs/render/raster_math.hpp"

namespace d2gs::render::cpu {

namespace {

constexpr int S = kTileSize;  // pixels per tile row = lanes of Row<T>

template <typename T>
struct SmoothConstants {
  static constexpr T alpha_lo = T(kSmoothAlphaLo);
  static constexpr T inv_alpha_range = T(1.0 / (kSmoothAlphaHi - kSmoothAlphaLo));
  static constexpr T power_lo = T(kSmoothPowerLo);
  static constexpr T inv_power_range = T(1.0 / (kSmoothPowerHi - kSmoothPowerLo));
};

// Lane-wise helpers on tile rows.
template <typename V>
inline V smoothstep_row(V e) {
  e = e < 0 ? V{} : e;
  e = e > 1 ? V{} + 1 : e;
  return e * e * (3 - 2 * e);
}
template <typename V>
inline V smoothstep_grad_row(V e) {
  return (e <= 0) | (e >= 1) ? V{} : 6 * e * (1 - e);
}
template <typename M>
inline bool any_lane(M m) {
  const M zero{};
  return std::memcmp(&m, &zero, sizeof m) != 0;
}

template <typename T, bool Smooth>
void forward_tile(const Binning<T>& bin, int tile, const T bg[3], T* rgb, T* alpha_out, T* depth_out,
                  PixelState<T>& state) {
  using V = typename Row<T>::V;
  using M = typename Row<T>::M;
  constexpr int VL = Row<T>::kLanes, C = S / VL;  // lanes per vector, vectors per tile row
  V Tr[S * C], cr[S * C], cg[S * C], cb[S * C], cd[S * C];
  M last[S * C], done[S * C];
  int row_alive[S];
  const int W = bin.width, H = bin.height;
  const int px0 = (tile % bin.tiles_x) * S, py0 = (tile / bin.tiles_x) * S;
  const int nrows = std::min(S, H - py0), ncols = std::min(S, W - px0);
  V xs[C];
  M outside_cols[C];
  for (int x = 0; x < S; ++x) {
    xs[x / VL][x % VL] = T(px0 + x);
    outside_cols[x / VL][x % VL] = x < ncols ? 0 : -1;
  }
  int alive = 0;
  for (int y = 0; y < S; ++y) {
    for (int c = 0; c < C; ++c) {
      const int k = y * C + c;
      Tr[k] = V{} + T(1);
      cr[k] = cg[k] = cb[k] = cd[k] = V{};
      last[k] = M{};
      done[k] = y < nrows ? outside_cols[c] : M{} - 1;
    }
    row_alive[y] = y < nrows ? ncols : 0;
    alive += row_alive[y];
  }
  const int begin = bin.tile_offsets[tile], end = bin.tile_offsets[tile + 1];
  for (int j = begin; j < end && alive > 0; ++j) {
    const Splat<T>& s = bin.splats[bin.isect_rank[j]];
    const int y_lo = std::max(s.y0 - py0, 0), y_hi = std::min(s.y1 - py0, nrows - 1);
    // Vectors of the row that the alpha box reaches (the box overlaps the tile, see binning).
    const int c_lo = std::max(s.x0 - px0, 0) / VL, c_hi = std::min(s.x1 - px0, S - 1) / VL;
    const M jl = M{} + (j - begin + 1);
    const T qa = s.qa, qb = s.qb, qc = s.qc, o = s.opacity;
    const T sr = s.r, sg = s.g, sb = s.b, sz = s.z;
    V dxs[C], hqa_dx2s[C];
    for (int c = 0; c < C; ++c) {
      dxs[c] = s.mx - xs[c];
      hqa_dx2s[c] = qa * dxs[c] * dxs[c];
    }
    M stopped{};
    for (int y = y_lo; y <= y_hi; ++y) {
      if (row_alive[y] == 0) continue;
      const T dy = s.my - T(py0 + y);
      for (int c = c_lo; c <= c_hi; ++c) {
      const int k = y * C + c;
      const V dx = dxs[c], hqa_dx2 = hqa_dx2s[c];
      const V power = T(-0.5) * (hqa_dx2 + qc * dy * dy) - qb * dx * dy;
      const V og = o * exp_row(power);
      V alpha = og < T(kAlphaMax) ? og : V{} + T(kAlphaMax);
      M ok;
      if constexpr (Smooth) {
        using K = SmoothConstants<T>;
        alpha = alpha * smoothstep_row((alpha - K::alpha_lo) * K::inv_alpha_range) *
                smoothstep_row((power - K::power_lo) * K::inv_power_range);
        ok = (power <= T(0)) & (alpha > T(0)) & ~done[k];
      } else {
        ok = (power <= T(0)) & (alpha >= T(kAlphaMin)) & ~done[k];
      }
      const V t_cur = Tr[k];
      const V t_next = t_cur * (T(1) - alpha);
      M stop{};
      if constexpr (!Smooth) stop = ok & (t_next < T(kTransmittanceMin));
      const M comp = ok & ~stop;
      const V w = comp ? alpha * t_cur : V{};
      cr[k] += w * sr;
      cg[k] += w * sg;
      cb[k] += w * sb;
      cd[k] += w * sz;
      Tr[k] = comp ? t_next : t_cur;
      last[k] = comp ? jl : last[k];
      done[k] |= stop;
      stopped |= stop;
      }
    }
    if (!Smooth && any_lane(stopped)) {  // some pixels are done: recount the rows they are in
      alive = 0;
      for (int y = 0; y < S; ++y) {
        int a = 0;
        for (int x = 0; x < S; ++x) a += done[y * C + x / VL][x % VL] == 0;
        row_alive[y] = a;
        alive += a;
      }
    }
  }
  for (int y = 0; y < nrows; ++y)
    for (int x = 0; x < ncols; ++x) {
      const std::size_t p = static_cast<std::size_t>(py0 + y) * W + (px0 + x);
      const int k = y * C + x / VL, l = x % VL;
      const T t = Tr[k][l];
      if (rgb) {
        rgb[p * 3 + 0] = cr[k][l] + t * bg[0];
        rgb[p * 3 + 1] = cg[k][l] + t * bg[1];
        rgb[p * 3 + 2] = cb[k][l] + t * bg[2];
      }
      if (alpha_out) alpha_out[p] = T(1) - t;
      if (depth_out) depth_out[p] = cd[k][l];
      state.final_transmittance[p] = t;
      state.n_contrib[p] = static_cast<int>(last[k][l]);
    }
}

template <typename T, bool Smooth>
void backward_tile(const Binning<T>& bin, int tile, const T bg[3], const PixelState<T>& state, const T* d_rgb,
                   const T* d_alpha, const T* d_depth, T* isect_grads) {
  using V = typename Row<T>::V;
  using M = typename Row<T>::M;
  constexpr int VL = Row<T>::kLanes, C = S / VL;
  V Tc[S * C], ar[S * C], ag[S * C], ab[S * C], ad[S * C], gr[S * C], gg[S * C], gb[S * C], gd[S * C], tgb[S * C];
  M last[S * C];
  int row_max[S];
  const int W = bin.width, H = bin.height;
  const int px0 = (tile % bin.tiles_x) * S, py0 = (tile / bin.tiles_x) * S;
  const int nrows = std::min(S, H - py0), ncols = std::min(S, W - px0);
  V xs[C];
  for (int x = 0; x < S; ++x) xs[x / VL][x % VL] = T(px0 + x);
  int tile_max = 0;
  for (int y = 0; y < S; ++y) {
    for (int c = 0; c < C; ++c) {
      const int k = y * C + c;
      Tc[k] = ar[k] = ag[k] = ab[k] = ad[k] = V{};
      gr[k] = gg[k] = gb[k] = gd[k] = tgb[k] = V{};
      last[k] = M{};
    }
    row_max[y] = 0;
    if (y >= nrows) continue;
    for (int x = 0; x < ncols; ++x) {
      const std::size_t p = static_cast<std::size_t>(py0 + y) * W + (px0 + x);
      const int k = y * C + x / VL, l = x % VL;
      Tc[k][l] = state.final_transmittance[p];
      last[k][l] = state.n_contrib[p];
      if (d_rgb) {
        gr[k][l] = d_rgb[p * 3 + 0];
        gg[k][l] = d_rgb[p * 3 + 1];
        gb[k][l] = d_rgb[p * 3 + 2];
      }
      if (d_depth) gd[k][l] = d_depth[p];
      const T ga = d_alpha ? d_alpha[p] : T(0);
      // d out / d alpha_i through T_final: T_final / (1 - alpha_i) * (d_alpha - bg . d_rgb).
      tgb[k][l] = Tc[k][l] * (ga - (bg[0] * gr[k][l] + bg[1] * gg[k][l] + bg[2] * gb[k][l]));
      row_max[y] = std::max(row_max[y], state.n_contrib[p]);
    }
    tile_max = std::max(tile_max, row_max[y]);
  }
  const int begin = bin.tile_offsets[tile];
  for (int jl = tile_max - 1; jl >= 0; --jl) {
    const Splat<T>& s = bin.splats[bin.isect_rank[begin + jl]];
    const int y_lo = std::max(s.y0 - py0, 0), y_hi = std::min(s.y1 - py0, nrows - 1);
    // Vectors of the row that the alpha box reaches (the box overlaps the tile, see binning).
    const int c_lo = std::max(s.x0 - px0, 0) / VL, c_hi = std::min(s.x1 - px0, S - 1) / VL;
    const T qa = s.qa, qb = s.qb, qc = s.qc, o = s.opacity;
    const T sr = s.r, sg = s.g, sb = s.b, sz = s.z;
    V dxs[C], hqa_dx2s[C];
    for (int c = 0; c < C; ++c) {
      dxs[c] = s.mx - xs[c];
      hqa_dx2s[c] = qa * dxs[c] * dxs[c];
    }
    const M jlv = M{} + jl;
    V v_mx{}, v_my{}, v_qa{}, v_qb{}, v_qc{}, v_o{}, v_r{}, v_g{}, v_b{}, v_z{};
    for (int y = y_lo; y <= y_hi; ++y) {
      if (row_max[y] <= jl) continue;
      const T dy = s.my - T(py0 + y);
      for (int c = c_lo; c <= c_hi; ++c) {
      const int k = y * C + c;
      const V dx = dxs[c], hqa_dx2 = hqa_dx2s[c];
      const V power = T(-0.5) * (hqa_dx2 + qc * dy * dy) - qb * dx * dy;
      const V G = exp_row(power);
      const V og = o * G;
      const V alpha_raw = og < T(kAlphaMax) ? og : V{} + T(kAlphaMax);
      V alpha = alpha_raw;
      V d_alpha_raw_scale = V{} + T(1), d_power_extra_scale{};
      M ok;
      if constexpr (Smooth) {
        using K = SmoothConstants<T>;
        const V ea = (alpha_raw - K::alpha_lo) * K::inv_alpha_range;
        const V ep = (power - K::power_lo) * K::inv_power_range;
        const V sa = smoothstep_row(ea), sp = smoothstep_row(ep);
        alpha = alpha_raw * sa * sp;
        d_alpha_raw_scale = (sa + alpha_raw * smoothstep_grad_row(ea) * K::inv_alpha_range) * sp;
        d_power_extra_scale = alpha_raw * sa * smoothstep_grad_row(ep) * K::inv_power_range;
        ok = (power <= T(0)) & (alpha > T(0)) & (jlv < last[k]);
      } else {
        ok = (power <= T(0)) & (alpha >= T(kAlphaMin)) & (jlv < last[k]);
      }
      const V one_m = T(1) - alpha;
      const V t_before = Tc[k] / one_m;
      const V w = alpha * t_before;
      const V g_alpha =
          t_before * ((sr - ar[k]) * gr[k] + (sg - ag[k]) * gg[k] + (sb - ab[k]) * gb[k] + (sz - ad[k]) * gd[k]) +
          tgb[k] / one_m;
      ar[k] = ok ? alpha * sr + one_m * ar[k] : ar[k];
      ag[k] = ok ? alpha * sg + one_m * ag[k] : ag[k];
      ab[k] = ok ? alpha * sb + one_m * ab[k] : ab[k];
      ad[k] = ok ? alpha * sz + one_m * ad[k] : ad[k];
      Tc[k] = ok ? t_before : Tc[k];
      v_r += ok ? w * gr[k] : V{};
      v_g += ok ? w * gg[k] : V{};
      v_b += ok ? w * gb[k] : V{};
      v_z += ok ? w * gd[k] : V{};
      // alpha_raw = min(0.99, o G): no gradient through the clamp.
      const V d_og = ok & (og < T(kAlphaMax)) ? g_alpha * d_alpha_raw_scale : V{};
      const V d_pow = d_og * og + (ok ? g_alpha * d_power_extra_scale : V{});
      v_o += d_og * G;
      v_mx -= d_pow * (qa * dx + qb * dy);
      v_my -= d_pow * (qb * dx + qc * dy);
      v_qa -= T(0.5) * d_pow * dx * dx;
      v_qb -= d_pow * dx * dy;
      v_qc -= T(0.5) * d_pow * (dy * dy);
      }
    }
    // Lane sums in a fixed order.
    T* out = isect_grads + static_cast<std::size_t>(begin + jl) * kIsectGradStride;
    const V* sums[kIsectGradStride] = {&v_mx, &v_my, &v_qa, &v_qb, &v_qc, &v_o, &v_r, &v_g, &v_b, &v_z};
    for (int k = 0; k < kIsectGradStride; ++k) {
      const V& v = *sums[k];
      T acc = T(0);
      for (int x = 0; x < VL; ++x) acc += v[x];
      out[k] = acc;
    }
  }
  // Intersections past the tile's last contributor get no gradient.
  const int count = bin.tile_offsets[tile + 1] - begin;
  for (int jl = tile_max; jl < count; ++jl) {
    T* out = isect_grads + static_cast<std::size_t>(begin + jl) * kIsectGradStride;
    for (int k = 0; k < kIsectGradStride; ++k) out[k] = T(0);
  }
}

}  // namespace

template <typename T>
void composite_forward(const Binning<T>& bin, const T background[3], bool smooth_cutoff, T* rgb, T* alpha,
                       T* depth, PixelState<T>& state) {
  const std::size_t pixels = static_cast<std::size_t>(bin.width) * bin.height;
  grow(state.final_transmittance, pixels);
  grow(state.n_contrib, pixels);
  const int n_tiles = bin.tiles_x * bin.tiles_y;
#pragma omp parallel for schedule(dynamic, 1)
  for (int tile = 0; tile < n_tiles; ++tile) {
    if (smooth_cutoff)
      forward_tile<T, true>(bin, tile, background, rgb, alpha, depth, state);
    else
      forward_tile<T, false>(bin, tile, background, rgb, alpha, depth, state);
  }
}

template <typename T>
void composite_backward(const Binning<T>& bin, const T background[3], bool smooth_cutoff,
                        const PixelState<T>& state, const T* d_rgb, const T* d_alpha, const T* d_depth,
                        std::size_t n, std::vector<T>& isect_grads, ProjectedGrads<T>& out) {
  grow(isect_grads, bin.intersections * kIsectGradStride);
  out.resize(n);
  const int n_tiles = bin.tiles_x * bin.tiles_y;
  T* ig = isect_grads.data();
#pragma omp parallel
  {
#pragma omp for schedule(dynamic, 1) nowait
    for (int tile = 0; tile < n_tiles; ++tile) {
      if (smooth_cutoff)
        backward_tile<T, true>(bin, tile, background, state, d_rgb, d_alpha, d_depth, ig);
      else
        backward_tile<T, false>(bin, tile, background, state, d_rgb, d_alpha, d_depth, ig);
    }
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
template void composite_backward<float>(const Binning<float>&, const float[3], bool, const PixelState<float>&,
                                        const float*, const float*, const float*, std::size_t,
                                        std::vector<float>&, ProjectedGrads<float>&);
template void composite_backward<double>(const Binning<double>&, const double[3], bool,
                                         const PixelState<double>&, const double*, const double*,
                                         const double*, std::size_t, std::vector<double>&,
                                         ProjectedGrads<double>&);

}  // namespace d2gs::render::cpu
