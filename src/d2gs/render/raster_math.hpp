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

}  // namespace d2gs::render
