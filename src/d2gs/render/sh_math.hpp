#pragma once
// Spherical harmonics -> RGB (method.md §2), forward and VJP, degrees 0..3, with the constants and
// sign conventions of the original 3DGS code. View direction = normalize(mean - camera centre);
// colour = SH(dir) + 0.5, clamped at >= 0 (the clamp is remembered: no gradient flows through a
// clamped channel). Coefficient k = 0 is sh_dc; k >= 1 is sh_rest[(k-1)*3 + c] (RGB innermost).
// D2GS_HD, templated on the scalar type, C++17.
#include "d2gs/render/projection_math.hpp"

namespace d2gs::render {

inline constexpr double kShC0 = 0.28209479177387814;
inline constexpr double kShC1 = 0.4886025119029199;
// Scalars rather than arrays so that device code can use them without __constant__ memory.
inline constexpr double kShC2_0 = 1.0925484305920792, kShC2_1 = -1.0925484305920792,
                        kShC2_2 = 0.31539156525252005, kShC2_3 = -1.0925484305920792,
                        kShC2_4 = 0.5462742152960396;
inline constexpr double kShC3_0 = -0.5900435899266435, kShC3_1 = 2.890611442640554,
                        kShC3_2 = -0.4570457994644658, kShC3_3 = 0.3731763325901154,
                        kShC3_4 = -0.4570457994644658, kShC3_5 = 1.445305721320277,
                        kShC3_6 = -0.5900435899266435;

// Basis values b[0..(deg+1)^2-1] at unit direction (x, y, z).
template <typename T>
D2GS_HD void sh_basis(int degree, T x, T y, T z, T b[16]) {
  b[0] = T(kShC0);
  if (degree < 1) return;
  b[1] = -T(kShC1) * y;
  b[2] = T(kShC1) * z;
  b[3] = -T(kShC1) * x;
  if (degree < 2) return;
  const T xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
  b[4] = T(kShC2_0) * xy;
  b[5] = T(kShC2_1) * yz;
  b[6] = T(kShC2_2) * (T(2) * zz - xx - yy);
  b[7] = T(kShC2_3) * xz;
  b[8] = T(kShC2_4) * (xx - yy);
  if (degree < 3) return;
  b[9] = T(kShC3_0) * y * (T(3) * xx - yy);
  b[10] = T(kShC3_1) * xy * z;
  b[11] = T(kShC3_2) * y * (T(4) * zz - xx - yy);
  b[12] = T(kShC3_3) * z * (T(2) * zz - T(3) * xx - T(3) * yy);
  b[13] = T(kShC3_4) * x * (T(4) * zz - xx - yy);
  b[14] = T(kShC3_5) * z * (xx - yy);
  b[15] = T(kShC3_6) * x * (xx - T(3) * yy);
}

// Partial derivatives of the basis w.r.t. x, y, z (direction treated as unconstrained).
template <typename T>
D2GS_HD void sh_basis_grad(int degree, T x, T y, T z, T bx[16], T by[16], T bz[16]) {
  for (int k = 0; k < 16; ++k) bx[k] = by[k] = bz[k] = T(0);
  if (degree < 1) return;
  by[1] = -T(kShC1);
  bz[2] = T(kShC1);
  bx[3] = -T(kShC1);
  if (degree < 2) return;
  const T xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
  bx[4] = T(kShC2_0) * y;  by[4] = T(kShC2_0) * x;
  by[5] = T(kShC2_1) * z;  bz[5] = T(kShC2_1) * y;
  bx[6] = T(kShC2_2) * (-T(2) * x);  by[6] = T(kShC2_2) * (-T(2) * y);  bz[6] = T(kShC2_2) * (T(4) * z);
  bx[7] = T(kShC2_3) * z;  bz[7] = T(kShC2_3) * x;
  bx[8] = T(kShC2_4) * (T(2) * x);  by[8] = T(kShC2_4) * (-T(2) * y);
  if (degree < 3) return;
  bx[9] = T(kShC3_0) * (T(6) * xy);
  by[9] = T(kShC3_0) * (T(3) * xx - T(3) * yy);
  bx[10] = T(kShC3_1) * yz;  by[10] = T(kShC3_1) * xz;  bz[10] = T(kShC3_1) * xy;
  bx[11] = T(kShC3_2) * (-T(2) * xy);
  by[11] = T(kShC3_2) * (T(4) * zz - xx - T(3) * yy);
  bz[11] = T(kShC3_2) * (T(8) * yz);
  bx[12] = T(kShC3_3) * (-T(6) * xz);
  by[12] = T(kShC3_3) * (-T(6) * yz);
  bz[12] = T(kShC3_3) * (T(6) * zz - T(3) * xx - T(3) * yy);
  bx[13] = T(kShC3_4) * (T(4) * zz - T(3) * xx - yy);
  by[13] = T(kShC3_4) * (-T(2) * xy);
  bz[13] = T(kShC3_4) * (T(8) * xz);
  bx[14] = T(kShC3_5) * (T(2) * xz);
  by[14] = T(kShC3_5) * (-T(2) * yz);
  bz[14] = T(kShC3_5) * (xx - yy);
  bx[15] = T(kShC3_6) * (T(3) * xx - T(3) * yy);
  by[15] = T(kShC3_6) * (-T(6) * xy);
}

// Unit view direction from the camera centre to the mean; returns |mean - campos|.
template <typename T>
D2GS_HD T view_direction(const T mean[3], const T campos[3], T dir[3]) {
  const T v0 = mean[0] - campos[0], v1 = mean[1] - campos[1], v2 = mean[2] - campos[2];
  const T len = hd_sqrt(v0 * v0 + v1 * v1 + v2 * v2);
  const T inv = len > T(0) ? T(1) / len : T(0);
  dir[0] = v0 * inv; dir[1] = v1 * inv; dir[2] = v2 * inv;
  return len;
}

// colour[c] = max(0, sum_k b_k sh_k[c] + 0.5); clamped[c] says whether the clamp was active.
template <typename T>
D2GS_HD void sh_to_color(int degree, const T* sh_dc, const T* sh_rest, const T mean[3], const T campos[3],
                         T color[3], bool clamped[3]) {
  T dir[3];
  view_direction(mean, campos, dir);
  T b[16];
  sh_basis(degree, dir[0], dir[1], dir[2], b);
  const int n = (degree + 1) * (degree + 1);
  for (int c = 0; c < 3; ++c) {
    T acc = b[0] * sh_dc[c];
    for (int k = 1; k < n; ++k) acc += b[k] * sh_rest[(k - 1) * 3 + c];
    acc += T(0.5);
    clamped[c] = acc < T(0);
    color[c] = clamped[c] ? T(0) : acc;
  }
}

// VJP: accumulates d_sh_dc, d_sh_rest (first (deg+1)^2-1 coefficients) and d_mean (+=).
template <typename T>
D2GS_HD void sh_to_color_vjp(int degree, const T* /*sh_dc*/, const T* sh_rest, const T mean[3], const T campos[3],
                             const bool clamped[3], const T d_color[3], T* d_sh_dc, T* d_sh_rest,
                             T d_mean[3]) {
  T dir[3];
  const T len = view_direction(mean, campos, dir);
  T b[16];
  sh_basis(degree, dir[0], dir[1], dir[2], b);
  const int n = (degree + 1) * (degree + 1);
  const T g[3] = {clamped[0] ? T(0) : d_color[0], clamped[1] ? T(0) : d_color[1],
                  clamped[2] ? T(0) : d_color[2]};
  for (int c = 0; c < 3; ++c) d_sh_dc[c] += b[0] * g[c];
  for (int k = 1; k < n; ++k)
    for (int c = 0; c < 3; ++c) d_sh_rest[(k - 1) * 3 + c] += b[k] * g[c];
  if (degree < 1 || !(len > T(0))) return;
  T bx[16], by[16], bz[16];
  sh_basis_grad(degree, dir[0], dir[1], dir[2], bx, by, bz);
  T ddir[3] = {0, 0, 0};
  for (int k = 1; k < n; ++k) {
    const T* s = sh_rest + (k - 1) * 3;
    const T w = s[0] * g[0] + s[1] * g[1] + s[2] * g[2];
    ddir[0] += bx[k] * w;
    ddir[1] += by[k] * w;
    ddir[2] += bz[k] * w;
  }
  // dir = v / |v|: dv = (ddir - dir (dir . ddir)) / |v|.
  const T dot = dir[0] * ddir[0] + dir[1] * ddir[1] + dir[2] * ddir[2];
  const T inv = T(1) / len;
  for (int k = 0; k < 3; ++k) d_mean[k] += (ddir[k] - dir[k] * dot) * inv;
}

}  // namespace d2gs::render
