#pragma once
// Per-pixel and per-tile math of alpha compositing (method.md §2), shared by the CPU and CUDA backends.
// D2GS_HD, templated on the scalar type, C++17.
//
// Per pixel p (integer coordinates in the original's frame, see projection_math.hpp) and Gaussian i in
// front-to-back order:  d = mean2d - p,  power = -1/2 d^T Q d,  skip if power > 0;
// alpha = min(0.99, opacity * exp(power)),  skip if alpha < 1/255;
// if T * (1 - alpha) < 1e-4 the pixel is done and i is NOT composited; otherwise
// C += alpha T colour,  D += alpha T z,  T *= 1 - alpha.  Output C + T background, alpha 1 - T.
//
// Gradient through the clamp alpha = min(0.99, o G), two rules (alpha_clamp_gradient_passes):
//   exact (default): d alpha / d(oG) = 1 below 0.99 and 0 where the clamp is active;
//   pass-through: d alpha / d(oG) = 1 everywhere, as the original rasterizer's backward.cu computes it
//   (dL/dG = o dL/dalpha, dL/do += G dL/dalpha whatever the clamp), not the derivative of its forward.
//
// Smooth cutoff (gradient checks only): alpha = min(0.99, o G) * S(min(0.99, o G)) * P(power) with
// S a C1 smoothstep from 0.5/255 to 1.5/255 and P a smoothstep of power from -4.5 to -4 (so alpha is 0
// where the 3-sigma tile rectangle may stop), no early stop. Everything is then continuous and almost
// everywhere differentiable in the parameters.
#include "d2gs/render/projection_math.hpp"

namespace d2gs::render {

inline constexpr double kAlphaMax = 0.99;
inline constexpr double kAlphaMin = 1.0 / 255.0;
inline constexpr double kTransmittanceMin = 1e-4;
inline constexpr double kSmoothAlphaLo = 0.5 / 255.0;   // smooth cutoff: alpha weight 0 below
inline constexpr double kSmoothAlphaHi = 1.5 / 255.0;   // ... and 1 above
inline constexpr double kSmoothPowerLo = -4.5;          // smooth cutoff: power weight 0 below
inline constexpr double kSmoothPowerHi = -4.0;

// The original's getRect: tiles [rect[0], rect[2]) x [rect[1], rect[3]) touched by the square of
// half-side `radius` around mean2d. Empty when the product of the sides is 0.
template <typename T>
D2GS_HD void tile_rect(T mx, T my, int radius, int tiles_x, int tiles_y, int rect[4]) {
  // Clamped in floating point before the conversion (same result as the original's int cast then
  // clamp, without overflow for far off-screen means).
  const T r = T(radius), ts = T(kTileSize);
  const T tx = T(tiles_x), ty = T(tiles_y);
  rect[0] = int(hd_min(tx, hd_max(T(0), (mx - r) / ts)));
  rect[1] = int(hd_min(ty, hd_max(T(0), (my - r) / ts)));
  rect[2] = int(hd_min(tx, hd_max(T(0), (mx + r + T(kTileSize - 1)) / ts)));
  rect[3] = int(hd_min(ty, hd_max(T(0), (my + r + T(kTileSize - 1)) / ts)));
}

// Whether d alpha / d(o G) is 1 (else 0) at og = o G under the chosen rule (see the header comment).
template <typename T>
D2GS_HD bool alpha_clamp_gradient_passes(T og, bool pass_through) {
  return pass_through || og < T(kAlphaMax);
}

template <typename T>
D2GS_HD T gaussian_power(T dx, T dy, T qa, T qb, T qc) {
  return T(-0.5) * (qa * dx * dx + qc * dy * dy) - qb * dx * dy;
}

// C1 smoothstep of e clamped to [0, 1], and its derivative.
template <typename T>
D2GS_HD T smoothstep01(T e) {
  e = hd_min(T(1), hd_max(T(0), e));
  return e * e * (T(3) - T(2) * e);
}
template <typename T>
D2GS_HD T smoothstep01_grad(T e) {
  return (e <= T(0) || e >= T(1)) ? T(0) : T(6) * e * (T(1) - e);
}

// Pixel bounding box (inclusive, integer pixel coordinates, may exceed the image) outside which a
// Gaussian of this opacity and conic cannot reach alpha >= alpha_min: d^T Q d <= 2 ln(o / alpha_min),
// whose half extents are sqrt(t Sigma_xx), sqrt(t Sigma_yy). A one-pixel margin absorbs rounding, so
// skipping pixels outside the box never changes a result. Returns false when no pixel can be reached.
template <typename T>
D2GS_HD bool alpha_pixel_box(T mx, T my, const T conic[3], T opacity, T alpha_min, int box[4]) {
  if (!(opacity >= alpha_min)) return false;
  const T t = T(2) * hd_log(opacity / alpha_min);
  const T det = conic[0] * conic[2] - conic[1] * conic[1];
  if (!(det > T(0))) return false;
  const T ex = hd_sqrt(t * conic[2] / det) + T(1);
  const T ey = hd_sqrt(t * conic[0] / det) + T(1);
  // Clamp to a range that fits an int before converting.
  const T lim = T(1 << 28);
  box[0] = int(hd_max(-lim, hd_floor(mx - ex)));
  box[1] = int(hd_min(lim, hd_ceil(mx + ex)));
  box[2] = int(hd_max(-lim, hd_floor(my - ey)));
  box[3] = int(hd_min(lim, hd_ceil(my + ey)));
  return true;
}

// The pixel columns of one row that a Gaussian can reach with alpha >= the cutoff: the x with
// q(mx - x, dy) <= reach (reach = 2 ln(opacity / cutoff), dy = my - row, inv_qa = 1 / qa), i.e. the chord
// of the ellipse through the row, widened for rounding (reach by 1e-3 relative, the ends by one pixel)
// so that skipping the columns outside [x_lo, x_hi] never changes a result. Returns false when the row
// misses the ellipse.
template <typename T>
D2GS_HD bool alpha_row_span(T mx, T dy, T qa, T qb, T qc, T reach, T inv_qa, T& x_lo, T& x_hi) {
  const T r = reach * T(1.001) + T(1e-4);
  const T disc = qa * r - dy * dy * (qa * qc - qb * qb);  // qa^2 (half chord)^2
  if (!(disc >= T(0))) return false;
  const T half = hd_sqrt(disc) * inv_qa;
  const T centre = mx + qb * dy * inv_qa;  // x of the chord's midpoint: dx = -qb dy / qa
  x_lo = centre - half - T(1);
  x_hi = centre + half + T(1);
  return true;
}

// ---- The tiles of a Gaussian's rectangle that the compositing would not visit ----
//
// A Gaussian's tile rectangle (tile_rect intersected with the tiles of alpha_pixel_box) holds every tile
// its ellipse q(d) = d^T Q d <= reach meets, and, for an elongated tilted ellipse, many it misses. The tile
// loops (SplatInTile::init in cpu/composite_tiles.ipp, the chord of alpha_row_span) visit row vector c of
// pixel row y of a tile only when y is a row of the image and of the alpha box, and, with dy = my - y,
//   disc = qa r1 - dy^2 det >= 0,   r1 = reach * 1.001 + 1e-4,   det = qa qc - qb qb,
//   [centre - half - 1, centre + half + 1] meets the vector's columns,
//   centre = mx + qb dy / qa,   half = sqrt(disc) / qa.
// A (Gaussian, tile) pair none of whose row vectors passes contributes nothing: no pixel composites the
// Gaussian, so images, transmittances and the backward's replay are unchanged, and the pair's gradient
// entries are (signed) zeros. A Gaussian's gradient is the sum of its pairs' entries starting from +0, and
// adding a zero to such a sum changes no bit (a float sum is -0 only when both terms are), so dropping
// the pair changes no result. tile_reach_columns drops only such pairs.
//
// The test, per tile row (band of pixel rows [y_lo, y_hi], dy in [p, q]). With k = qb / qa and
// e = det / qa, the chord of row dy is centred at mx + k dy, and its half length h(dy) =
// sqrt((r1 - e dy^2) / qa) is largest at the row nearest the centre, dy_n = clamp(0, p, q). So every chord
// of the band lies within [mx + min(k p, k q) - H, mx + max(k p, k q) + H], H = h(dy_n) (no row of the band
// has a chord when r1 < e dy_n^2), and a tile whose columns widened by one pixel on each side, [16 tx - 1,
// 16 tx + 16], miss that interval is visited in no row. For a circle or an axis-aligned ellipse (k = 0)
// this is the exact chord test; for a tilted one it is looser (it keeps more), at the cost of one square
// root per tile row instead of a test per tile.
//
// Rounding. Margins far beyond the rounding of either side make it err only towards keeping:
//  - det: this det and the tile loops' float det may differ by up to 2 eps (qa qc + qb^2) (each rounds
//    its products and difference; FMA contraction, on the GPU or with -march=native, rounds one product
//    less). The test uses det - 4 eps (qa qc + qb^2), below the tile loops' det, which only lengthens
//    the chords; when that is not positive (an ellipse with an axis ratio beyond about 2000) every tile
//    is kept.
//  - reach: R = reach * 1.002 + 2e-4 in place of r1, 1e-3 relative more. That covers the rounding of
//    disc there (within the chord's rows its two terms are at most about qa r1, so it rounds by a few eps
//    relative to qa r1; the square root of that error is what lengthens a chord near the ellipse's tips,
//    and R - e dy^2 exceeds r1 - e dy^2 by far more), of R - e dy_n^2 here, of r1, and of a logarithm
//    that another math library rounds differently.
//  - positions: the rows' dy range [p, q] and the interval of the chords are widened by 1/16 pixel +
//    16 eps (|mx| + |my| + 2 extent + 32 |k| + 64), extent = sqrt(R / qa) + |k| sqrt(R / e) (bounds of H and
//    of |k dy| within the ellipse; 32 |k| for the band's rows beyond it), beyond the rounding of dy,
//    centre, half and the chord's ends there and of p, q, k p, k q, H and the tile bounds here (each a few
//    eps of those magnitudes). Multiplying by 1/16 is exact.
// tests/render/test_tile_cull.cpp checks, for random and elongated Gaussians, that no row of a dropped
// tile has a chord (alpha_row_span) that meets it and no pixel centre of it reaches the alpha cutoff, and
// that renders and gradients are bit-identical with and without the cull.
template <typename T>
D2GS_HD T hd_abs(T a) {
  return a < T(0) ? -a : a;
}
template <typename T>
D2GS_HD constexpr T hd_epsilon() {  // machine epsilon of T (float or double)
  return sizeof(T) == sizeof(float) ? T(1.1920928955078125e-7) : T(2.220446049250313e-16);
}

// Per Gaussian, what tile_reach_columns needs. `all`: keep every tile (no test).
template <typename T>
struct TileReach {
  bool all = true;
  T mx = 0, my = 0, inv_qa = 0, k = 0, e = 0, R = 0, margin = 0;
  int y0 = 0, y1 = -1;  // the alpha box's pixel rows (inclusive)
  int height = 0;       // image rows
};

// reach = 2 ln(opacity / alpha_min) (the Splat's), box = alpha_pixel_box's.
template <typename T>
D2GS_HD TileReach<T> tile_reach_setup(T mx, T my, const T conic[3], T reach, const int box[4], int height) {
  TileReach<T> t;
  const T qa = conic[0], qb = conic[1], qc = conic[2];
  const T eps = hd_epsilon<T>();
  const T det_lo = (qa * qc - qb * qb) - T(4) * eps * (qa * qc + qb * qb);
  if (!(qa > T(0)) || !(det_lo > T(0)) || !(reach > T(0))) return t;
  t.all = false;
  t.mx = mx;
  t.my = my;
  t.y0 = box[2];
  t.y1 = box[3];
  t.height = height;
  t.inv_qa = T(1) / qa;
  t.k = qb * t.inv_qa;
  t.e = det_lo * t.inv_qa;
  t.R = reach * T(1.002) + T(2e-4);
  const T extent = hd_sqrt(t.R * t.inv_qa) + hd_abs(t.k) * hd_sqrt(t.R / t.e);
  t.margin = T(0.0625) + T(16) * eps * (hd_abs(mx) + hd_abs(my) + T(2) * extent + T(32) * hd_abs(t.k) + T(64));
  return t;
}

// The tile columns [x0, x1) of rect (x0 x1 as rect[0], rect[2]) in tile row ty that the tile loops may
// visit (empty: x0 == x1); the whole of them when t.all.
template <typename T>
D2GS_HD void tile_reach_columns(const TileReach<T>& t, int ty, const int rect[4], int& x0, int& x1) {
  x0 = rect[0];
  x1 = rect[2];
  if (t.all) return;
  const int y_lo = hd_max(ty * kTileSize, t.y0);
  const int y_hi = hd_min(hd_min(ty * kTileSize + kTileSize - 1, t.height - 1), t.y1);
  const T p = (t.my - T(y_hi)) - t.margin, q = (t.my - T(y_lo)) + t.margin;
  const T dy_n = hd_min(q, hd_max(p, T(0)));
  const T disc = t.R - t.e * dy_n * dy_n;
  if (y_lo > y_hi || disc < T(0)) {  // no row of the band holds a chord
    x1 = x0;
    return;
  }
  const T H = hd_sqrt(disc * t.inv_qa);
  const T kp = t.k * p, kq = t.k * q;
  // Tile tx is kept when [16 tx - 1, 16 tx + 16] meets [mx + min - H - margin, mx + max + H + margin].
  const T lo = ((t.mx + (hd_min(kp, kq) - H - t.margin)) - T(kTileSize)) * T(1.0 / kTileSize);
  const T hi = ((t.mx + (hd_max(kp, kq) + H + t.margin)) + T(1)) * T(1.0 / kTileSize);
  const T c = hd_ceil(lo), f = hd_floor(hi);
  // Clamped in floating point before the conversion (far coordinates); NaN keeps the whole row.
  if (c > T(rect[0])) x0 = c < T(rect[2]) ? int(c) : rect[2];
  if (f < T(rect[2] - 1)) x1 = f >= T(x0) ? int(f) + 1 : x0;
}

// Calls emit(tx, ty) for the tiles of rect [x0, x1) x [y0, y1) that tile_reach_columns keeps, row by row
// and left to right, and returns their count.
template <typename T, class Emit>
D2GS_HD int for_each_reached_tile(const TileReach<T>& t, const int rect[4], Emit&& emit) {
  int count = 0;
  for (int ty = rect[1]; ty < rect[3]; ++ty) {
    int x0, x1;
    tile_reach_columns(t, ty, rect, x0, x1);
    for (int tx = x0; tx < x1; ++tx) emit(tx, ty);
    count += x1 - x0;
  }
  return count;
}

}  // namespace d2gs::render
