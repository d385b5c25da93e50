#pragma once
// The per-pixel arithmetic of alpha compositing (raster_math.hpp's rules) in float, one pixel and one
// Gaussian at a time, exactly as the CPU tile loops (cpu/composite_tiles.ipp) compute each of their SIMD
// lanes: the same operations in the same order, the same exp polynomial, fused multiply-adds where the
// tile loops write fmadd. The compositing kernels of the CUDA backend (kernels/composite_kernels.hpp)
// call these functions, so their per-pixel values are the CPU's bit for bit.
//
// `Fused` is whether the tile loops' fmadd is one rounding (x86-64-v3 and v4, and the GPU: fmaf) or two
// (the SSE2 baseline: a * b + c, contraction off). Lane-wise, the levels differ in nothing else.
// D2GS_HD, C++17, float only (the double tile loops are the gradient checks' and use the libm exp).
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "d2gs/render/raster_math.hpp"

namespace d2gs::render {

// Constants of the exp polynomial (Cephes-style range reduction x = n ln2 + r and a degree-6 polynomial;
// cpu/simd_math.hpp's exp_row builds its vectors from these).
inline constexpr float kExpLo = -80.0f;  // inputs below give exp(-80): "0" to a cutoff of 1/255, no denormals
inline constexpr float kExpHi = 88.0f;
inline constexpr float kExpLog2e = 1.44269504088896341f;
inline constexpr float kExpRound = 12582912.0f;  // 1.5 * 2^23: adding and subtracting rounds to an integer
inline constexpr float kExpLn2Hi = -0.693359375f;
inline constexpr float kExpLn2Lo = 2.12194440e-4f;
inline constexpr float kExpC0 = 1.9875691500e-4f;
inline constexpr float kExpC1 = 1.3981999507e-3f;
inline constexpr float kExpC2 = 8.3334519073e-3f;
inline constexpr float kExpC3 = 4.1665795894e-2f;
inline constexpr float kExpC4 = 1.6666665459e-1f;
inline constexpr float kExpC5 = 5.0000001201e-1f;

// The float constants of compositing, as the tile loops convert raster_math.hpp's doubles.
inline constexpr float kAlphaMaxF = float(kAlphaMax);
inline constexpr float kAlphaMinF = float(kAlphaMin);
inline constexpr float kTransmittanceMinF = float(kTransmittanceMin);
inline constexpr float kSmoothAlphaLoF = float(kSmoothAlphaLo);
inline constexpr float kSmoothInvAlphaRangeF = float(1.0 / (kSmoothAlphaHi - kSmoothAlphaLo));
inline constexpr float kSmoothPowerLoF = float(kSmoothPowerLo);
inline constexpr float kSmoothInvPowerRangeF = float(1.0 / (kSmoothPowerHi - kSmoothPowerLo));

// a * b + c rounded once (correctly rounded on both sides: CUDA's fmaf, glibc's fmaf).
D2GS_HD float hd_fmaf(float a, float b, float c) {
#if defined(__CUDA_ARCH__)
  return __fmaf_rn(a, b, c);
#else
  return fmaf(a, b, c);
#endif
}

// The tile loops' fmadd: fused, or a product and a sum each rounded.
template <bool Fused>
D2GS_HD float fmadd_f(float a, float b, float c) {
  if constexpr (Fused) {
    return hd_fmaf(a, b, c);
  } else {
    const float p = a * b;
    return p + c;
  }
}

D2GS_HD float float_from_bits(uint32_t bits) {
#if defined(__CUDA_ARCH__)
  return __uint_as_float(bits);
#else
  float v;
  memcpy(&v, &bits, sizeof v);
  return v;
#endif
}

// exp(x) for x <= 0 to about 1 ulp: exp_row of cpu/simd_math.hpp for one lane.
template <bool Fused>
D2GS_HD float composite_exp(float x) {
  x = kExpLo > x ? kExpLo : x;  // lane_max(lo, x)
  x = kExpHi < x ? kExpHi : x;  // lane_min(hi, x)
  const float n = fmadd_f<Fused>(x, kExpLog2e, kExpRound) - kExpRound;
  float r = fmadd_f<Fused>(n, kExpLn2Hi, x);
  r = fmadd_f<Fused>(n, kExpLn2Lo, r);
  const float r2 = r * r;
  float p = kExpC0;
  p = fmadd_f<Fused>(p, r, kExpC1);
  p = fmadd_f<Fused>(p, r, kExpC2);
  p = fmadd_f<Fused>(p, r, kExpC3);
  p = fmadd_f<Fused>(p, r, kExpC4);
  p = fmadd_f<Fused>(p, r, kExpC5);
  const float y = fmadd_f<Fused>(p, r2, r) + 1.0f;
  const uint32_t bits = static_cast<uint32_t>(static_cast<int32_t>(n) + 127) << 23;
  return y * float_from_bits(bits);
}

// The tile loops' smoothstep of (e clamped to [0, 1]) and its derivative, lane for lane.
D2GS_HD float composite_smoothstep(float e) {
  e = 0.0f > e ? 0.0f : e;
  e = 1.0f < e ? 1.0f : e;
  return e * e * (3.0f - 2.0f * e);
}
D2GS_HD float composite_smoothstep_grad(float e) { return (e <= 0.0f || e >= 1.0f) ? 0.0f : 6.0f * e * (1.0f - e); }

// What compositing needs of one Gaussian (the first fields of cpu::Splat).
struct SplatParams {
  float mx, my, qa, qb, qc, opacity, r, g, b, z;
};

// One (pixel, Gaussian) evaluation: the forward's and the backward's alpha, from the same operations.
struct SplatAlpha {
  float dx, dy, power, G, og, alpha;
  float d_alpha_raw_scale, d_power_extra_scale;  // smooth cutoff: d alpha / d alpha_raw, d alpha / d power
  bool ok;  // power <= 0 and alpha reaches the cutoff
};

// Pixel (x, y) in the original's frame (pixel centres at integers). power = -1/2 d^T Q d is evaluated as
// the tile loops do: (-qa/2) dx dx + (-qc/2) dy dy + (0 - qb dy) dx, the last product fused.
template <bool Smooth, bool Fused>
D2GS_HD SplatAlpha splat_alpha(const SplatParams& s, float x, float y) {
  SplatAlpha e;
  e.dx = s.mx - x;
  e.dy = s.my - y;
  const float hx = (-0.5f * s.qa) * e.dx * e.dx;
  const float hy = (-0.5f * s.qc) * e.dy * e.dy;
  const float by = 0.0f + -s.qb * e.dy;
  e.power = fmadd_f<Fused>(by - 0.0f, e.dx, hx + hy);
  e.G = composite_exp<Fused>(e.power);
  e.og = s.opacity * e.G;
  const float alpha_raw = e.og < kAlphaMaxF ? e.og : kAlphaMaxF;  // lane_min(og, 0.99)
  e.d_alpha_raw_scale = 1.0f;
  e.d_power_extra_scale = 0.0f;
  if constexpr (Smooth) {
    const float ea = (alpha_raw - kSmoothAlphaLoF) * kSmoothInvAlphaRangeF;
    const float ep = (e.power - kSmoothPowerLoF) * kSmoothInvPowerRangeF;
    const float sa = composite_smoothstep(ea), sp = composite_smoothstep(ep);
    e.alpha = alpha_raw * sa * sp;
    e.d_alpha_raw_scale = (sa + alpha_raw * composite_smoothstep_grad(ea) * kSmoothInvAlphaRangeF) * sp;
    e.d_power_extra_scale = alpha_raw * sa * composite_smoothstep_grad(ep) * kSmoothInvPowerRangeF;
    e.ok = e.power <= 0.0f && e.alpha > 0.0f;
  } else {
    e.alpha = alpha_raw;
    e.ok = e.power <= 0.0f && e.alpha >= kAlphaMinF;
  }
  return e;
}

// ---- forward: front to back ----

struct PixelForward {
  float t, r, g, b, depth;  // transmittance, accumulated colour and depth
  int last;                 // 1 + index (in the tile's list) of the last Gaussian composited; 0 = none
  int done;                 // the pixel stopped (T would fall below 1e-4) or lies outside the image
};

D2GS_HD void pixel_forward_init(PixelForward& p, bool inside) {
  p.t = 1.0f;
  p.r = p.g = p.b = p.depth = 0.0f;
  p.last = 0;
  p.done = inside ? 0 : 1;
}

// Gaussian number `index` (0-based, in the tile's list) over the pixel. The hard cutoff stops the pixel,
// without compositing this Gaussian, when T (1 - alpha) < 1e-4; the smooth cutoff never stops.
template <bool Smooth, bool Fused>
D2GS_HD void pixel_forward_step(PixelForward& p, const SplatParams& s, float x, float y, int index) {
  if (p.done) return;
  const SplatAlpha e = splat_alpha<Smooth, Fused>(s, x, y);
  if (!e.ok) return;
  const float t_next = p.t * (1.0f - e.alpha);
  if (!Smooth && t_next < kTransmittanceMinF) {
    p.done = 1;
    return;
  }
  const float w = e.alpha * p.t;
  p.r = fmadd_f<Fused>(w, s.r, p.r);
  p.g = fmadd_f<Fused>(w, s.g, p.g);
  p.b = fmadd_f<Fused>(w, s.b, p.b);
  p.depth = fmadd_f<Fused>(w, s.z, p.depth);
  p.t = t_next;
  p.last = index + 1;
}

// The pixel's outputs: colour over the background, alpha = 1 - T, depth = sum alpha_i T_i z_i.
D2GS_HD void pixel_forward_outputs(const PixelForward& p, const float bg[3], float rgb[3], float& alpha, float& depth) {
  rgb[0] = p.r + p.t * bg[0];
  rgb[1] = p.g + p.t * bg[1];
  rgb[2] = p.b + p.t * bg[2];
  alpha = 1.0f - p.t;
  depth = p.depth;
}

// ---- backward: back to front from the final transmittance ----

struct PixelBackward {
  float t;                  // transmittance after the Gaussians still to be visited (T_final at first)
  float ar, ag, ab, ad;     // colour and depth of what lies behind the current Gaussian
  float gr, gg, gb, gd;     // d loss / d colour, d loss / d depth of the pixel
  float tgb;                // T_final (d loss / d alpha - background . d loss / d colour)
  int last;                 // PixelForward::last (0 outside the image)
};

// d_rgb: the pixel's three values or null; d_alpha, d_depth: 0 when not given.
D2GS_HD void pixel_backward_init(PixelBackward& p, float final_t, int last, const float* d_rgb, float d_alpha,
                                 float d_depth, const float bg[3]) {
  p.t = final_t;
  p.last = last;
  p.ar = p.ag = p.ab = p.ad = 0.0f;
  p.gr = d_rgb ? d_rgb[0] : 0.0f;
  p.gg = d_rgb ? d_rgb[1] : 0.0f;
  p.gb = d_rgb ? d_rgb[2] : 0.0f;
  p.gd = d_depth;
  // d out / d alpha_i through T_final: T_final / (1 - alpha_i) * (d_alpha - bg . d_rgb).
  p.tgb = p.t * (d_alpha - (bg[0] * p.gr + bg[1] * p.gg + bg[2] * p.gb));
}

// One pixel's share of the gradient of one Gaussian: the sums over pixels of d loss / d power times dx,
// dy, dx^2, dx dy, dy^2 (from which the mean2d and conic gradients follow, splat_grad_finish), and the
// opacity, colour and depth gradients.
struct SplatGrad {
  float x, y, xx, xy, yy, o, r, g, b, z;
};

D2GS_HD void splat_grad_zero(SplatGrad& g) { g.x = g.y = g.xx = g.xy = g.yy = g.o = g.r = g.g = g.b = g.z = 0.0f; }
D2GS_HD void splat_grad_add(SplatGrad& a, const SplatGrad& b) {
  a.x += b.x;
  a.y += b.y;
  a.xx += b.xx;
  a.xy += b.xy;
  a.yy += b.yy;
  a.o += b.o;
  a.r += b.r;
  a.g += b.g;
  a.b += b.b;
  a.z += b.z;
}

// Gaussian number `index` of the tile's list, visited back to front. Returns false (g untouched) where it
// was not composited into this pixel; otherwise g = this pixel's terms and the pixel's state steps in
// front of the Gaussian. clamp_pass_through: raster_math.hpp's alpha_clamp_gradient_passes rule.
template <bool Smooth, bool Fused>
D2GS_HD bool pixel_backward_step(PixelBackward& p, const SplatParams& s, float x, float y, int index,
                                 bool clamp_pass_through, SplatGrad& g) {
  if (index >= p.last) return false;
  const SplatAlpha e = splat_alpha<Smooth, Fused>(s, x, y);
  if (!e.ok) return false;
  const float one_m = 1.0f - e.alpha;
  const float inv_one_m = 1.0f / one_m;
  const float t_before = p.t * inv_one_m;
  const float wk = e.alpha * t_before;
  // Depth, blue, green, red: the tile loops' order of the sum d out / d alpha = sum_c (c_i - behind_c) g_c.
  float d_behind = (s.z - p.ad) * p.gd;
  g.z = wk * p.gd;
  p.ad = fmadd_f<Fused>(e.alpha, s.z, one_m * p.ad);
  d_behind = fmadd_f<Fused>(s.b - p.ab, p.gb, d_behind);
  g.b = wk * p.gb;
  p.ab = fmadd_f<Fused>(e.alpha, s.b, one_m * p.ab);
  d_behind = fmadd_f<Fused>(s.g - p.ag, p.gg, d_behind);
  g.g = wk * p.gg;
  p.ag = fmadd_f<Fused>(e.alpha, s.g, one_m * p.ag);
  d_behind = fmadd_f<Fused>(s.r - p.ar, p.gr, d_behind);
  g.r = wk * p.gr;
  p.ar = fmadd_f<Fused>(e.alpha, s.r, one_m * p.ar);
  const float g_alpha = fmadd_f<Fused>(t_before, d_behind, p.tgb * inv_one_m);
  p.t = t_before;
  const bool passes = alpha_clamp_gradient_passes(e.og, clamp_pass_through);
  const float d_og = passes ? g_alpha * e.d_alpha_raw_scale : 0.0f;
  float d_pow = d_og * e.og;
  if constexpr (Smooth) d_pow += g_alpha * e.d_power_extra_scale;
  g.o = d_og * e.G;
  const float d_pow_dx = d_pow * e.dx;
  g.x = d_pow_dx;
  g.xx = d_pow_dx * e.dx;
  g.xy = d_pow_dx * e.dy;
  g.y = d_pow * e.dy;
  g.yy = d_pow * (e.dy * e.dy);
  return true;
}

// The projected-quantity gradients of a sum of SplatGrad terms: d power / d (mx, my, qa, qb, qc) =
// -(qa dx + qb dy, qb dx + qc dy, dx^2 / 2, dx dy, dy^2 / 2). Out: mean2d[2], conic[3], opacity,
// colour[3], depth, the order of the CPU's intersection gradients (kIsectGradStride).
D2GS_HD void splat_grad_finish(const SplatGrad& g, const SplatParams& s, float out[10]) {
  out[0] = -(s.qa * g.x + s.qb * g.y);
  out[1] = -(s.qb * g.x + s.qc * g.y);
  out[2] = -0.5f * g.xx;
  out[3] = -g.xy;
  out[4] = -0.5f * g.yy;
  out[5] = g.o;
  out[6] = g.r;
  out[7] = g.g;
  out[8] = g.b;
  out[9] = g.z;
}

}  // namespace d2gs::render
