#pragma once
// The per-pixel arithmetic of SSIM (eval/ssim.cpp), shared unchanged by the CPU's Ssim<T> and the CUDA
// backend's SSIM kernels (train/kernels/ssim_kernels.hpp). C++17, no standard library: nvcc compiles it.
//
// Local statistics are the outputs of the 11-tap separable Gaussian blur: mu = G*a, s_aa = G*(a²),
// s_bb = G*(b²), s_ab = G*(a·b). The SSIM map at a pixel is
//   S = (2·mu_a·mu_b + C1)(2·cov + C2) / ((mu_a² + mu_b² + C1)(var_a + var_b + C2)),
// and its local derivatives (scaled by g) are blurred once more and combined into d(mean S)/da by
// ssim_input_gradient (G is self-adjoint).
#include "d2gs/core/host_device.hpp"

namespace d2gs {

inline constexpr int kSsimWindow = 11;
inline constexpr double kSsimSigma = 1.5;
inline constexpr double kSsimC1 = 0.01 * 0.01;
inline constexpr double kSsimC2 = 0.03 * 0.03;

// The SSIM map value at one pixel; with Grad also dS/dmu_a, dS/d<a²>, dS/d<ab>, each times g.
template <typename T, bool Grad>
D2GS_HD T ssim_pixel(T ma, T mb, T s_aa, T s_bb, T s_ab, T C1, T C2, T g, T* d_mu, T* d_saa, T* d_sab) {
  const T var_a = s_aa - ma * ma, var_b = s_bb - mb * mb, cov = s_ab - ma * mb;
  const T A1 = T(2) * ma * mb + C1, A2 = T(2) * cov + C2;
  const T B1 = ma * ma + mb * mb + C1, B2 = var_a + var_b + C2;
  const T inv_b = T(1) / (B1 * B2);
  const T s = A1 * A2 * inv_b;
  if constexpr (Grad) {
    *d_mu = g * ((T(2) * mb * A2 - T(2) * mb * A1) * inv_b - s * (T(2) * ma / B1 - T(2) * ma / B2));
    *d_saa = g * (-s / B2);
    *d_sab = g * (T(2) * A1 * inv_b);
  } else {
    (void)g, (void)d_mu, (void)d_saa, (void)d_sab;
  }
  return s;
}

// d(mean S)/da at one value from the blurred local derivatives: G*(dS/dmu_a) + 2a·G*(dS/d<a²>) +
// b·G*(dS/d<ab>). Callers add it to the gradient buffer (which holds the other loss terms' gradients).
template <typename T>
D2GS_HD T ssim_input_gradient(T blurred_d_mu, T a, T blurred_d_saa, T b, T blurred_d_sab) {
  return blurred_d_mu + T(2) * a * blurred_d_saa + b * blurred_d_sab;
}

}  // namespace d2gs
