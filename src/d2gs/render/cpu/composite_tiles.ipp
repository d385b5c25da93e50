// The tile loops of alpha compositing (raster_math.hpp), forward and backward. Not a header: each
// composite_tiles_<level>.cpp defines D2GS_TILE_ISA (the namespace, e.g. avx2) and includes this file
// once, compiled for its x86-64 level (see composite_tiles.hpp and src/d2gs/render/CMakeLists.txt).
//
// Inside a tile the 256 pixels are SIMD lanes in structure-of-arrays buffers on the stack; for each
// Gaussian of the tile list only the pixel rows (and row vectors) of its alpha box are visited, with
// masks instead of branches inside a row vector. Rows, and the tile, whose pixels are all done are
// skipped. The forward and the backward kernel evaluate alpha through the same function, and the
// translation units are compiled with -ffp-contract=off, so the backward replays exactly the forward's
// per-pixel decisions.
#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>

#include "d2gs/render/cpu/composite_tiles.hpp"
#include "d2gs/render/cpu/simd_math.hpp"
#include "d2gs/render/raster_math.hpp"

namespace d2gs::render::cpu::D2GS_TILE_ISA {

namespace {

constexpr int S = kTileSize;  // pixels per tile row

template <typename T>
struct SmoothConstants {
  static constexpr T alpha_lo = T(kSmoothAlphaLo);
  static constexpr T inv_alpha_range = T(1.0 / (kSmoothAlphaHi - kSmoothAlphaLo));
  static constexpr T power_lo = T(kSmoothPowerLo);
  static constexpr T inv_power_range = T(1.0 / (kSmoothPowerHi - kSmoothPowerLo));
};

// Lane-wise helpers on tile rows.
template <typename V>
D2GS_TILE_INLINE V smoothstep_row(V e) {
  e = lane_max(V{}, e);      // e < 0 ? 0 : e
  e = lane_min(V{} + 1, e);  // e > 1 ? 1 : e
  return e * e * (3 - 2 * e);
}
template <typename V>
D2GS_TILE_INLINE V smoothstep_grad_row(V e) {
  return ((e <= 0) | (e >= 1)) ? V{} : 6 * e * (1 - e);
}

// What one Gaussian contributes to a tile, precomputed once per (Gaussian, tile): per column vector dx =
// mean_x - x and -1/2 qa dx^2; per pixel row dy = mean_y - y, -1/2 qc dy^2 and -qb dy; and which row
// vectors hold pixels the Gaussian can reach (the chord of raster_math.hpp's alpha_row_span through the
// row, widened for rounding, so skipping the others never changes a result). The rows are the lanes of
// that computation (a tile's S rows are C vectors), so the test costs a few vector instructions per
// (Gaussian, tile) instead of a scalar square root per row.
template <typename T>
struct SplatInTile {
  using V = typename Row<T>::V;
  using M = typename Row<T>::M;
  static constexpr int VL = Row<T>::kLanes;
  static constexpr int C = S / VL;  // vectors per tile row, and groups of VL rows per tile
  std::uint32_t rows;     // bit y: row y of the tile holds pixels the Gaussian can reach
  std::uint32_t vecs[C];  // bit y of vecs[c]: row vector c of row y does
  V dx[C], hx[C];
  alignas(sizeof(V)) T dy[S];
  alignas(sizeof(V)) T hy[S];
  alignas(sizeof(V)) T by[S];
  // xs: the tile's pixel x per column vector; ys: its pixel y per group of rows; rs: the row index
  // within the tile (0 … S-1) per group of rows.
  D2GS_TILE_INLINE void init(const Splat<T>& s, int px0, int py0, int nrows, const V xs[C], const V ys[C],
                             const V rs[C]) {
    for (int c = 0; c < C; ++c) {
      dx[c] = s.mx - xs[c];
      hx[c] = (T(-0.5) * s.qa) * dx[c] * dx[c];
      vecs[c] = 0;
    }
    rows = 0;
    const int y_lo = std::max(s.y0 - py0, 0), y_hi = std::min(s.y1 - py0, nrows - 1);
    if (y_lo > y_hi) return;
    const T reach = s.reach * T(1.001) + T(1e-4);
    const T qa_reach = s.qa * reach, det = s.qa * s.qc - s.qb * s.qb;
    for (int g = y_lo / VL; g <= y_hi / VL; ++g) {
      const V d = s.my - ys[g];
      const V disc = qa_reach - d * d * det;  // qa^2 (half chord)^2
      const M ok = (disc >= T(0)) & (rs[g] >= T(y_lo)) & (rs[g] <= T(y_hi));
      const V half = sqrt_row(select_or_zero(ok, disc)) * s.inv_qa;
      const V centre = s.mx + s.qb * d * s.inv_qa;  // x of the chord's midpoint
      const V x_lo = centre - half - T(1), x_hi = centre + half + T(1);
      for (int c = 0; c < C; ++c)
        vecs[c] |= lane_bits(ok & (x_lo <= T(px0 + c * VL + VL - 1)) & (x_hi >= T(px0 + c * VL))) << (g * VL);
      // by holds 0 + (-qb dy), the term row_power adds as it is (the sum with 0 turns a -0 into +0).
      const V h = (T(-0.5) * s.qc) * d * d, b = V{} + -s.qb * d;
      std::memcpy(&dy[g * VL], &d, sizeof(V));
      std::memcpy(&hy[g * VL], &h, sizeof(V));
      std::memcpy(&by[g * VL], &b, sizeof(V));
    }
    for (int c = 0; c < C; ++c) rows |= vecs[c];
  }
  // Whether row vector c of row y is visited (every row in `rows` visits at least one).
  D2GS_TILE_INLINE bool visits(int y, int c) const {
    if constexpr (C == 1) return true;
    return (vecs[c] >> y) & 1u;
  }
};

// power = -1/2 d^T Q d for one row vector, as -1/2 qa dx^2 (per column) + (-1/2 qc dy^2 - qb dy dx) (per
// row): the one formula both passes use.
template <typename V, typename T>
D2GS_TILE_INLINE V row_power(V hx, V dx, T hy, T by) {
  // by is already 0 + (-qb dy) (init); by - 0 is by in every lane, a plain broadcast.
  return fmadd(by - V{}, dx, hx + hy);
}

// The splats of a tile list are scattered over the depth-sorted array (a cache miss each): fetch the
// one kPrefetch entries ahead while the current one is composited.
constexpr int kPrefetch = 8;
template <typename T>
D2GS_TILE_INLINE void prefetch_splat(const Binning<T>& bin, int j) {
  const Splat<T>* p = &bin.splats[bin.isect_rank[j]];
  __builtin_prefetch(p);
  if constexpr (sizeof(Splat<T>) > 64) __builtin_prefetch(reinterpret_cast<const char*>(p) + 64);
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
  V xs[C], ys[C], rs[C];
  M outside_cols[C];
  for (int x = 0; x < S; ++x) {
    xs[x / VL][x % VL] = T(px0 + x);
    ys[x / VL][x % VL] = T(py0 + x);
    rs[x / VL][x % VL] = T(x);
    outside_cols[x / VL][x % VL] = x < ncols ? 0 : -1;
  }
  int alive = 0;
  std::uint32_t alive_rows = 0;  // bit y: row y has pixels still compositing
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
    if (row_alive[y] > 0) alive_rows |= 1u << y;
  }
  const int begin = bin.tile_offsets[tile], end = bin.tile_offsets[tile + 1];
  const auto* ek = exp_constants();
  SplatInTile<T> st;
  for (int j = begin; j < std::min(end, begin + kPrefetch); ++j) prefetch_splat(bin, j);
  for (int j = begin; j < end && alive > 0; ++j) {
    if (j + kPrefetch < end) prefetch_splat(bin, j + kPrefetch);
    const Splat<T>& s = bin.splats[bin.isect_rank[j]];
    st.init(s, px0, py0, nrows, xs, ys, rs);
    const M jl = M{} + (j - begin + 1);
    const T o = s.opacity;
    const V vr = V{} + s.r, vg = V{} + s.g, vb = V{} + s.b, vz = V{} + s.z;
    for (std::uint32_t todo = st.rows & alive_rows; todo != 0; todo &= todo - 1) {
      const int y = std::countr_zero(todo);
      const T hy = st.hy[y], by = st.by[y];
      int stopped_in_row = 0;
      for (int c = 0; c < C; ++c) {
        if (!st.visits(y, c)) continue;
        const int k = y * C + c;
        const V power = row_power(st.hx[c], st.dx[c], hy, by);
        const V og = o * exp_row(power, *ek);
        V alpha = lane_min(og, V{} + T(kAlphaMax));  // og < 0.99 ? og : 0.99
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
        const V w = select_or_zero(comp, alpha * t_cur);
        cr[k] = fmadd(w, vr, cr[k]);
        cg[k] = fmadd(w, vg, cg[k]);
        cb[k] = fmadd(w, vb, cb[k]);
        cd[k] = fmadd(w, vz, cd[k]);
        Tr[k] = select(comp, t_next, t_cur);
        last[k] = select(comp, jl, last[k]);
        if constexpr (!Smooth) {
          if (any_lane(stop)) {  // some pixels are done: they leave the row's and the tile's count
            done[k] |= stop;
            stopped_in_row += count_lanes(stop);
          }
        }
      }
      row_alive[y] -= stopped_in_row;
      alive -= stopped_in_row;
      if (row_alive[y] == 0) alive_rows &= ~(1u << y);
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

// Depth: whether the loss has a depth gradient (d_depth). Without one (every method but the stereo-depth
// regulariser) the depth channel's terms are left out: its gradient is zero, so they added only zeros.
template <typename T, bool Smooth, bool Depth>
void backward_tile(const Binning<T>& bin, int tile, const T bg[3], bool clamp_pass_through, const PixelState<T>& state,
                   const T* d_rgb, const T* d_alpha, const T* d_depth, T* isect_grads) {
  using V = typename Row<T>::V;
  using M = typename Row<T>::M;
  constexpr int VL = Row<T>::kLanes, C = S / VL;
  V Tc[S * C], ar[S * C], ag[S * C], ab[S * C], ad[S * C], gr[S * C], gg[S * C], gb[S * C], gd[S * C], tgb[S * C];
  M last[S * C];
  int row_max[S];
  const int W = bin.width, H = bin.height;
  const int px0 = (tile % bin.tiles_x) * S, py0 = (tile / bin.tiles_x) * S;
  const int nrows = std::min(S, H - py0), ncols = std::min(S, W - px0);
  V xs[C], ys[C], rs[C];
  for (int x = 0; x < S; ++x) {
    xs[x / VL][x % VL] = T(px0 + x);
    ys[x / VL][x % VL] = T(py0 + x);
    rs[x / VL][x % VL] = T(x);
  }
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
  const auto* ek = exp_constants();
  SplatInTile<T> st;
  for (int jl = tile_max - 1; jl >= std::max(0, tile_max - kPrefetch); --jl) prefetch_splat(bin, begin + jl);
  for (int jl = tile_max - 1; jl >= 0; --jl) {
    if (jl - kPrefetch >= 0) prefetch_splat(bin, begin + jl - kPrefetch);
    const Splat<T>& s = bin.splats[bin.isect_rank[begin + jl]];
    st.init(s, px0, py0, nrows, xs, ys, rs);
    const T qa = s.qa, qb = s.qb, qc = s.qc, o = s.opacity;
    const T sr = s.r, sg = s.g, sb = s.b, sz = s.z;
    const V vr = V{} + sr, vg = V{} + sg, vb = V{} + sb, vz = V{} + sz;
    const M jlv = M{} + jl;
    // d power / d (mx, my, qa, qb, qc) = -(qa dx + qb dy, qb dx + qc dy, dx^2 / 2, dx dy, dy^2 / 2): the
    // five sums below of g = d loss / d power (times dx, dy, dx^2, dx dy, dy^2) give all five gradients.
    V a_x{}, a_y{}, a_xx{}, a_xy{}, a_yy{}, v_o{}, v_r{}, v_g{}, v_b{}, v_z{};
    for (std::uint32_t todo = st.rows; todo != 0; todo &= todo - 1) {
      const int y = std::countr_zero(todo);
      if (row_max[y] <= jl) continue;
      const T dy = st.dy[y], hy = st.hy[y], by = st.by[y];
      const V dyv = V{} + dy, dy2v = V{} + dy * dy;
      for (int c = 0; c < C; ++c) {
        if (!st.visits(y, c)) continue;
        const int k = y * C + c;
        const V dx = st.dx[c];
        const V power = row_power(st.hx[c], dx, hy, by);
        const V G = exp_row(power, *ek);
        const V og = o * G;
        const V alpha_raw = lane_min(og, V{} + T(kAlphaMax));  // og < 0.99 ? og : 0.99
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
        if (!any_lane(ok)) continue;
        const V one_m = T(1) - alpha;
        const V inv_one_m = T(1) / one_m;
        const V t_before = Tc[k] * inv_one_m;
        const V wk = select_or_zero(ok, alpha * t_before);
        // Per channel (depth, blue, green, red: the nesting order of the sum below), so that each
        // channel's loads die at once (fewer spills): d out / d alpha's sum over the channels,
        // sum_c (colour_c - behind_c) grad_c, the colour gradient w grad_c, and the colour behind this
        // Gaussian updated to include it.
        V d_behind{};
        if constexpr (Depth) {
          const V g = gd[k], a = ad[k];
          d_behind = (sz - a) * g;
          v_z = fmadd(wk, g, v_z);
          ad[k] = select(ok, fmadd(alpha, vz, one_m * a), a);
        }
        {
          const V g = gb[k], a = ab[k];
          d_behind = fmadd(sb - a, g, d_behind);
          v_b = fmadd(wk, g, v_b);
          ab[k] = select(ok, fmadd(alpha, vb, one_m * a), a);
        }
        {
          const V g = gg[k], a = ag[k];
          d_behind = fmadd(sg - a, g, d_behind);
          v_g = fmadd(wk, g, v_g);
          ag[k] = select(ok, fmadd(alpha, vg, one_m * a), a);
        }
        {
          const V g = gr[k], a = ar[k];
          d_behind = fmadd(sr - a, g, d_behind);
          v_r = fmadd(wk, g, v_r);
          ar[k] = select(ok, fmadd(alpha, vr, one_m * a), a);
        }
        const V g_alpha = fmadd(t_before, d_behind, tgb[k] * inv_one_m);
        Tc[k] = select(ok, t_before, Tc[k]);
        // alpha_raw = min(0.99, o G): the lane-wise alpha_clamp_gradient_passes of raster_math.hpp (no gradient
        // through an active clamp, unless the original's pass-through rule is chosen).
        const M passes = clamp_pass_through ? ok : ok & (og < T(kAlphaMax));
        const V d_og = select_or_zero(passes, g_alpha * d_alpha_raw_scale);
        V d_pow = d_og * og;
        if constexpr (Smooth) d_pow += select_or_zero(ok, g_alpha * d_power_extra_scale);
        v_o = fmadd(d_og, G, v_o);
        const V d_pow_dx = d_pow * dx;
        a_x += d_pow_dx;
        a_xx = fmadd(d_pow_dx, dx, a_xx);
        a_xy = fmadd(d_pow_dx, dyv, a_xy);
        a_y = fmadd(d_pow, dyv, a_y);
        a_yy = fmadd(d_pow, dy2v, a_yy);
      }
    }
    // Lane sums in a fixed order.
    T* out = isect_grads + static_cast<std::size_t>(begin + jl) * kIsectGradStride;
    T sums[8];
    sum_lanes4(a_x, a_y, a_xx, a_xy, sums);
    sum_lanes4(v_r, v_g, v_b, v_z, sums + 4);
    const T sx = sums[0], sy = sums[1];
    out[0] = -(qa * sx + qb * sy);
    out[1] = -(qb * sx + qc * sy);
    out[2] = T(-0.5) * sums[2];
    out[3] = -sums[3];
    out[4] = T(-0.5) * sum_lanes(a_yy);
    out[5] = sum_lanes(v_o);
    out[6] = sums[4];
    out[7] = sums[5];
    out[8] = sums[6];
    out[9] = sums[7];
  }
  // Intersections past the tile's last contributor get no gradient.
  const int count = bin.tile_offsets[tile + 1] - begin;
  for (int jl = tile_max; jl < count; ++jl) {
    T* out = isect_grads + static_cast<std::size_t>(begin + jl) * kIsectGradStride;
    for (int k = 0; k < kIsectGradStride; ++k) out[k] = T(0);
  }
}

template <typename T>
void forward_entry(const Binning<T>& bin, int tile, const T background[3], bool smooth_cutoff, T* rgb, T* alpha,
                   T* depth, PixelState<T>& state) {
  if (smooth_cutoff)
    forward_tile<T, true>(bin, tile, background, rgb, alpha, depth, state);
  else
    forward_tile<T, false>(bin, tile, background, rgb, alpha, depth, state);
}

template <typename T>
void backward_entry(const Binning<T>& bin, int tile, const T background[3], bool smooth_cutoff,
                    bool clamp_pass_through, const PixelState<T>& state, const T* d_rgb, const T* d_alpha,
                    const T* d_depth, T* isect_grads) {
  const auto run = [&]<bool Smooth, bool Depth>() {
    backward_tile<T, Smooth, Depth>(bin, tile, background, clamp_pass_through, state, d_rgb, d_alpha, d_depth,
                                    isect_grads);
  };
  if (smooth_cutoff)
    d_depth ? run.template operator()<true, true>() : run.template operator()<true, false>();
  else
    d_depth ? run.template operator()<false, true>() : run.template operator()<false, false>();
}

#define D2GS_TILE_STR2(x) #x
#define D2GS_TILE_STR(x) D2GS_TILE_STR2(x)

}  // namespace

const TileKernels<float>& kernels_float() {
  static const TileKernels<float> k{D2GS_TILE_STR(D2GS_TILE_ISA), &forward_entry<float>, &backward_entry<float>};
  return k;
}
#ifdef D2GS_TILE_WITH_DOUBLE
const TileKernels<double>& kernels_double() {
  static const TileKernels<double> k{D2GS_TILE_STR(D2GS_TILE_ISA), &forward_entry<double>,
                                     &backward_entry<double>};
  return k;
}
#endif

}  // namespace d2gs::render::cpu::D2GS_TILE_ISA
