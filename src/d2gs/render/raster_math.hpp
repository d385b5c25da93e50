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
// Gaussian, so the images, the per-pixel contributor counts' meaning and the backward's replay are
// unchanged, and the pair's gradient entries are (signed) zeros; a Gaussian's gradient is the sum of its
// pairs' entries starting from +0, and adding a zero to a sum that starts from +0 changes no bit (a sum
// of floats is -0 only when both terms are). tile_reach_keeps drops a tile only in that case.
//
// The test. With k = qb / qa and e = det / qa, row dy passes for some column of the tile (columns
// X0 ... X1) only if dist(mx + k dy, [X0 - 1, X1 + 1]) <= half, that is (squaring, times qa)
//   f(dy) = qa dist(k dy, [a, b])^2 + e dy^2 <= r1,   [a, b] = [X0 - 1 - mx, X1 + 1 - mx]
// (which implies disc >= 0). f is convex (the distance of a linear function to an interval is convex
// and non-negative, so is its square; e > 0) and differentiable, so its minimisers over the reals solve
// f' = 0: dy = 0 where k dy lies in [a, b], dy = qa k a / (qa k^2 + e) where k dy < a, and
// dy = qa k b / (qa k^2 + e) where k dy > b. The minimum of f over the tile's rows [p, q] is therefore f
// at one of those three points clamped to [p, q], and the smallest of f at the three clamped points is
// exactly min f over [p, q] (each is a point of [p, q]). The tile is dropped when it exceeds R >= r1.
//
// Rounding. Margins far beyond the rounding of either side make the test err only towards keeping:
//  - det: this det and the tile loops' float det may differ by up to 2 eps (qa qc + qb^2) (each rounds
//    its products and difference; FMA contraction, on the GPU or with -march=native, rounds one product
//    less). The test uses det - 4 eps (qa qc + qb^2), below the tile loops' det, which only lengthens
//    the chords; when that is not positive (an ellipse with an axis ratio beyond about 2000) every tile
//    is kept.
//  - reach: R = reach * 1.002 + 2e-4, 1e-3 relative above r1. That covers the rounding of disc (within
//    the chord's rows its two terms are at most about qa r1, so it rounds by a few eps relative to
//    qa r1), of r1 and of a logarithm that another math library rounds differently, of f here (a sum of
//    non-negative terms: a few eps relative), and of the three minimisers (an error in the point enters
//    f to second order: at most (a few eps)^2 times the axis-ratio squared, relative, below 1e-6 for the
//    axis ratios the det bound admits).
//  - positions: the rows' dy range and [a, b] are widened by 1/16 pixel + 16 eps (|mx| + |my| + 2
//    extent + 64), extent = sqrt(R / qa) + |k| sqrt(R / e) (bounds of half and of |k dy| within the
//    ellipse), beyond the rounding of dy, centre, half and the chord's ends there and of a, b, p, q here
//    (each a few eps of those magnitudes).
// tests/render/test_tile_cull.cpp checks, for random and elongated Gaussians, that no pixel of a dropped
// tile reaches the alpha cutoff and no row of it has a chord (alpha_row_span) that meets the tile, and
// that renders and gradients are bit-identical with and without the test.
template <typename T>
D2GS_HD T hd_abs(T a) {
  return a < T(0) ? -a : a;
}
template <typename T>
D2GS_HD constexpr T hd_epsilon() {  // machine epsilon of T (float or double)
  return sizeof(T) == sizeof(float) ? T(1.1920928955078125e-7) : T(2.220446049250313e-16);
}

// Per Gaussian, what tile_reach_keeps needs. `all`: keep every tile (no test).
template <typename T>
struct TileReach {
  bool all = true;
  T mx = 0, my = 0, qa = 0, k = 0, e = 0, c1 = 0, R = 0, margin = 0;
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
  const T inv_qa = T(1) / qa;
  t.qa = qa;
  t.k = qb * inv_qa;
  t.e = det_lo * inv_qa;
  t.c1 = qa * t.k / (qa * t.k * t.k + t.e);
  t.R = reach * T(1.002) + T(2e-4);
  const T extent = hd_sqrt(t.R * inv_qa) + hd_abs(t.k) * hd_sqrt(t.R / t.e);
  t.margin = T(0.0625) + T(16) * eps * (hd_abs(mx) + hd_abs(my) + T(2) * extent + T(64));
  return t;
}

// The dy = my - y range [p, q] of the rows of tile row ty that the tile loops may visit (image and alpha
// box rows), widened by the margin. False when there are none.
template <typename T>
D2GS_HD bool tile_reach_rows(const TileReach<T>& t, int ty, T& p, T& q) {
  const int y_lo = hd_max(ty * kTileSize, t.y0);
  const int y_hi = hd_min(hd_min(ty * kTileSize + kTileSize - 1, t.height - 1), t.y1);
  if (y_lo > y_hi) return false;
  p = (t.my - T(y_hi)) - t.margin;
  q = (t.my - T(y_lo)) + t.margin;
  return true;
}

// Whether tile column tx, in the tile row of [p, q], may hold a row vector the tile loops visit.
template <typename T>
D2GS_HD bool tile_reach_keeps(const TileReach<T>& t, int tx, T p, T q) {
  const T a = (T(tx * kTileSize - 1) - t.mx) - t.margin;
  const T b = (T(tx * kTileSize + kTileSize) - t.mx) + t.margin;
  T f[3];
  const T at[3] = {T(0), t.c1 * a, t.c1 * b};
  for (int j = 0; j < 3; ++j) {
    const T dy = hd_min(q, hd_max(p, at[j]));
    const T u = t.k * dy;
    const T dist = hd_max(hd_max(a - u, u - b), T(0));
    f[j] = t.qa * dist * dist + t.e * dy * dy;
  }
  return !(hd_min(f[0], hd_min(f[1], f[2])) > t.R);  // keeps on NaN
}

// Calls emit(tx, ty) for the tiles of rect [x0, x1) x [y0, y1) that tile_reach_keeps keeps, row by row
// and left to right, and returns their count. In each tile row the tiles between the first and the last
// kept one are kept without a test (the kept tiles of a row are contiguous in exact arithmetic: the
// ellipse's part within the row is convex; keeping more is always safe).
template <typename T, class Emit>
D2GS_HD int for_each_reached_tile(const TileReach<T>& t, const int rect[4], Emit&& emit) {
  int count = 0;
  for (int ty = rect[1]; ty < rect[3]; ++ty) {
    int x0 = rect[0], x1 = rect[2];
    if (!t.all) {
      T p = 0, q = 0;
      if (!tile_reach_rows(t, ty, p, q)) continue;
      while (x0 < x1 && !tile_reach_keeps(t, x0, p, q)) ++x0;
      while (x1 - 1 > x0 && !tile_reach_keeps(t, x1 - 1, p, q)) --x1;
    }
    for (int tx = x0; tx < x1; ++tx) emit(tx, ty);
    count += x1 - x0;
  }
  return count;
}

}  // namespace d2gs::render
