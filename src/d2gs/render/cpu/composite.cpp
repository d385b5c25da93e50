#include "d2gs/render/cpu/composite.hpp"

#include <algorithm>

#include "d2gs/render/cpu/simd_math.hpp"
#include "d2gs/render/raster_math.hpp"

namespace d2gs::render::cpu {

namespace {

constexpr int S = kTileSize;
constexpr int L = S * S;

template <typename T>
struct SmoothConstants {
  static constexpr T alpha_lo = T(kSmoothAlphaLo);
  static constexpr T inv_alpha_range = T(1.0 / (kSmoothAlphaHi - kSmoothAlphaLo));
  static constexpr T power_lo = T(kSmoothPowerLo);
  static constexpr T inv_power_range = T(1.0 / (kSmoothPowerHi - kSmoothPowerLo));
};

template <typename T, bool Smooth>
void forward_tile(const Binning<T>& bin, int tile, const T bg[3], T* rgb, T* alpha_out, T* depth_out,
                  PixelState<T>& state) {
  alignas(64) T Tr[L], cr[L], cg[L], cb[L], cd[L];
  alignas(64) int last[L], done[L];
  int row_alive[S];
  const int W = bin.width, H = bin.height;
  const int px0 = (tile % bin.tiles_x) * S, py0 = (tile / bin.tiles_x) * S;
  const int nrows = std::min(S, H - py0), ncols = std::min(S, W - px0);
  int alive = 0;
  for (int y = 0; y < S; ++y) {
    row_alive[y] = 0;
    for (int x = 0; x < S; ++x) {
      const int l = y * S + x;
      const bool inside = y < nrows && x < ncols;
      Tr[l] = T(1);
      cr[l] = cg[l] = cb[l] = cd[l] = T(0);
      last[l] = 0;
      done[l] = inside ? 0 : 1;
      row_alive[y] += inside ? 1 : 0;
    }
    alive += row_alive[y];
  }
  const int begin = bin.tile_offsets[tile], end = bin.tile_offsets[tile + 1];
  for (int j = begin; j < end && alive > 0; ++j) {
    const Splat<T>& s = bin.splats[bin.isect_rank[j]];
    const int y_lo = std::max(s.y0 - py0, 0), y_hi = std::min(s.y1 - py0, nrows - 1);
    const int jl = j - begin + 1;
    const T mx = s.mx, qa = s.qa, qb = s.qb, qc = s.qc, o = s.opacity;
    const T sr = s.r, sg = s.g, sb = s.b, sz = s.z;
    for (int y = y_lo; y <= y_hi; ++y) {
      if (row_alive[y] == 0) continue;
      const T dy = s.my - T(py0 + y);
      T* tr = Tr + y * S;
      T* r_ = cr + y * S;
      T* g_ = cg + y * S;
      T* b_ = cb + y * S;
      T* d_ = cd + y * S;
      int* la = last + y * S;
      int* dn = done + y * S;
      int newly_done = 0;
#pragma omp simd reduction(+ : newly_done)
      for (int x = 0; x < S; ++x) {
        const T dx = mx - T(px0 + x);
        const T power = T(-0.5) * (qa * dx * dx + qc * dy * dy) - qb * dx * dy;
        const T og = o * exp_lanes(power);
        T alpha = og < T(kAlphaMax) ? og : T(kAlphaMax);
        bool ok;
        if constexpr (Smooth) {
          using K = SmoothConstants<T>;
          alpha = alpha * smoothstep01((alpha - K::alpha_lo) * K::inv_alpha_range) *
                  smoothstep01((power - K::power_lo) * K::inv_power_range);
          ok = (power <= T(0)) & (alpha > T(0)) & (dn[x] == 0);
        } else {
          ok = (power <= T(0)) & (alpha >= T(kAlphaMin)) & (dn[x] == 0);
        }
        const T t_cur = tr[x];
        const T t_next = t_cur * (T(1) - alpha);
        const bool stop = Smooth ? false : (ok & (t_next < T(kTransmittanceMin)));
        const bool comp = ok & !stop;
        const T w = comp ? alpha * t_cur : T(0);
        r_[x] += w * sr;
        g_[x] += w * sg;
        b_[x] += w * sb;
        d_[x] += w * sz;
        tr[x] = comp ? t_next : t_cur;
        la[x] = comp ? jl : la[x];
        dn[x] = stop ? 1 : dn[x];
        newly_done += stop ? 1 : 0;
      }
      row_alive[y] -= newly_done;
      alive -= newly_done;
    }
  }
  for (int y = 0; y < nrows; ++y)
    for (int x = 0; x < ncols; ++x) {
      const int l = y * S + x;
      const std::size_t p = static_cast<std::size_t>(py0 + y) * W + (px0 + x);
      if (rgb) {
        rgb[p * 3 + 0] = cr[l] + Tr[l] * bg[0];
        rgb[p * 3 + 1] = cg[l] + Tr[l] * bg[1];
        rgb[p * 3 + 2] = cb[l] + Tr[l] * bg[2];
      }
      if (alpha_out) alpha_out[p] = T(1) - Tr[l];
      if (depth_out) depth_out[p] = cd[l];
      state.final_transmittance[p] = Tr[l];
      state.n_contrib[p] = last[l];
    }
}

template <typename T, bool Smooth>
void backward_tile(const Binning<T>& bin, int tile, const T bg[3], const PixelState<T>& state, const T* d_rgb,
                   const T* d_alpha, const T* d_depth, T* isect_grads) {
  alignas(64) T Tc[L], ar[L], ag[L], ab[L], ad[L], gr[L], gg[L], gb[L], gd[L], tgb[L];
  alignas(64) int last[L];
  int row_max[S];
  const int W = bin.width, H = bin.height;
  const int px0 = (tile % bin.tiles_x) * S, py0 = (tile / bin.tiles_x) * S;
  const int nrows = std::min(S, H - py0), ncols = std::min(S, W - px0);
  int tile_max = 0;
  for (int y = 0; y < S; ++y) {
    row_max[y] = 0;
    for (int x = 0; x < S; ++x) {
      const int l = y * S + x;
      Tc[l] = ar[l] = ag[l] = ab[l] = ad[l] = T(0);
      gr[l] = gg[l] = gb[l] = gd[l] = tgb[l] = T(0);
      last[l] = 0;
      if (y >= nrows || x >= ncols) continue;
      const std::size_t p = static_cast<std::size_t>(py0 + y) * W + (px0 + x);
      Tc[l] = state.final_transmittance[p];
      last[l] = state.n_contrib[p];
      if (d_rgb) {
        gr[l] = d_rgb[p * 3 + 0];
        gg[l] = d_rgb[p * 3 + 1];
        gb[l] = d_rgb[p * 3 + 2];
      }
      if (d_depth) gd[l] = d_depth[p];
      const T ga = d_alpha ? d_alpha[p] : T(0);
      // d out / d alpha_i through T_final: T_final / (1 - alpha_i) * (d_alpha - bg . d_rgb).
      tgb[l] = Tc[l] * (ga - (bg[0] * gr[l] + bg[1] * gg[l] + bg[2] * gb[l]));
      row_max[y] = std::max(row_max[y], last[l]);
    }
    tile_max = std::max(tile_max, row_max[y]);
  }
  const int begin = bin.tile_offsets[tile];
  for (int jl = tile_max - 1; jl >= 0; --jl) {
    const Splat<T>& s = bin.splats[bin.isect_rank[begin + jl]];
    const int y_lo = std::max(s.y0 - py0, 0), y_hi = std::min(s.y1 - py0, nrows - 1);
    const T mx = s.mx, qa = s.qa, qb = s.qb, qc = s.qc, o = s.opacity;
    const T sr = s.r, sg = s.g, sb = s.b, sz = s.z;
    T g_mx = 0, g_my = 0, g_qa = 0, g_qb = 0, g_qc = 0, g_o = 0, g_r = 0, g_g = 0, g_b = 0, g_z = 0;
    for (int y = y_lo; y <= y_hi; ++y) {
      if (row_max[y] <= jl) continue;
      const T dy = s.my - T(py0 + y);
      const int o_ = y * S;
      T* tc = Tc + o_;
      T* a_r = ar + o_;
      T* a_g = ag + o_;
      T* a_b = ab + o_;
      T* a_d = ad + o_;
      const T* grr = gr + o_;
      const T* ggg = gg + o_;
      const T* gbb = gb + o_;
      const T* gdd = gd + o_;
      const T* tg = tgb + o_;
      const int* la = last + o_;
#pragma omp simd reduction(+ : g_mx, g_my, g_qa, g_qb, g_qc, g_o, g_r, g_g, g_b, g_z)
      for (int x = 0; x < S; ++x) {
        const T dx = mx - T(px0 + x);
        const T power = T(-0.5) * (qa * dx * dx + qc * dy * dy) - qb * dx * dy;
        const T G = exp_lanes(power);
        const T og = o * G;
        const T alpha_raw = og < T(kAlphaMax) ? og : T(kAlphaMax);
        T alpha = alpha_raw;
        T d_alpha_raw_scale = T(1), d_power_extra_scale = T(0);
        bool ok;
        if constexpr (Smooth) {
          using K = SmoothConstants<T>;
          const T ea = (alpha_raw - K::alpha_lo) * K::inv_alpha_range;
          const T ep = (power - K::power_lo) * K::inv_power_range;
          const T sa = smoothstep01(ea), sp = smoothstep01(ep);
          alpha = alpha_raw * sa * sp;
          d_alpha_raw_scale = (sa + alpha_raw * smoothstep01_grad(ea) * K::inv_alpha_range) * sp;
          d_power_extra_scale = alpha_raw * sa * smoothstep01_grad(ep) * K::inv_power_range;
          ok = (power <= T(0)) & (alpha > T(0)) & (jl < la[x]);
        } else {
          ok = (power <= T(0)) & (alpha >= T(kAlphaMin)) & (jl < la[x]);
        }
        const T one_m = T(1) - alpha;
        const T t_before = tc[x] / one_m;
        const T w = alpha * t_before;
        const T g_alpha = t_before * ((sr - a_r[x]) * grr[x] + (sg - a_g[x]) * ggg[x] + (sb - a_b[x]) * gbb[x] +
                                      (sz - a_d[x]) * gdd[x]) +
                          tg[x] / one_m;
        a_r[x] = ok ? alpha * sr + one_m * a_r[x] : a_r[x];
        a_g[x] = ok ? alpha * sg + one_m * a_g[x] : a_g[x];
        a_b[x] = ok ? alpha * sb + one_m * a_b[x] : a_b[x];
        a_d[x] = ok ? alpha * sz + one_m * a_d[x] : a_d[x];
        tc[x] = ok ? t_before : tc[x];
        g_r += ok ? w * grr[x] : T(0);
        g_g += ok ? w * ggg[x] : T(0);
        g_b += ok ? w * gbb[x] : T(0);
        g_z += ok ? w * gdd[x] : T(0);
        // alpha_raw = min(0.99, o G): no gradient through the clamp.
        const T d_og = (ok & (og < T(kAlphaMax))) ? g_alpha * d_alpha_raw_scale : T(0);
        const T d_pow = d_og * og + (ok ? g_alpha * d_power_extra_scale : T(0));
        g_o += d_og * G;
        g_mx -= d_pow * (qa * dx + qb * dy);
        g_my -= d_pow * (qb * dx + qc * dy);
        g_qa -= T(0.5) * d_pow * dx * dx;
        g_qb -= d_pow * dx * dy;
        g_qc -= T(0.5) * d_pow * dy * dy;
      }
    }
    T* out = isect_grads + static_cast<std::size_t>(begin + jl) * kIsectGradStride;
    out[0] = g_mx; out[1] = g_my;
    out[2] = g_qa; out[3] = g_qb; out[4] = g_qc;
    out[5] = g_o;
    out[6] = g_r; out[7] = g_g; out[8] = g_b;
    out[9] = g_z;
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
