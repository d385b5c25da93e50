#pragma once
// The per-Gaussian arithmetic of DD-Drop's probabilities (train/dropout.cpp: gaussian_depths, minmax,
// depth_layers, dd_drop_probabilities), shared unchanged by the CPU and the CUDA backend's kernels
// (train/kernels/dd_drop_kernels.hpp). C++17, no standard library: nvcc compiles it.
//
//   p_i = clamp(λ_layer(i) · S_i · r(t), 0, 1),  S_i = w_d·(1 − minmax(d_i)) + w_ρ·minmax(ρ_i)   (method.md §4)
#include <math.h>

#include "d2gs/core/host_device.hpp"

namespace d2gs {

// The per-iteration constants of p_i (dd_drop_terms in dropout.hpp makes them from DdDropOptions).
struct DdDropTerms {
  double weight_depth = 0.0;    // w_d
  double weight_density = 0.0;  // w_ρ
  double lambdas[3] = {1.0, 1.0, 1.0};  // near, middle, far
  double rate = 0.0;            // r(t)
  bool use_depth_score = true;
  bool use_density_score = true;
  bool use_layers = true;
};

// The depth tertiles' ranks in the ascending depths: ⌊0.33·N⌋ and ⌊0.67·N⌋, at most N − 1 (N ≥ 1).
inline constexpr double kNearTertile = 0.33, kFarTertile = 0.67;
D2GS_HD long long tertile_rank(long long n, double quantile) {
  const long long k = static_cast<long long>(quantile * static_cast<double>(n));
  return k < n - 1 ? k : n - 1;
}

// Depth of a Gaussian at (x, y, z): its Euclidean distance to the camera centre c (the paper), in double
// as glm::length(x − c) computes it (products rounded, summed x + y then + z), rounded to float once.
D2GS_HD float dd_drop_depth_euclidean(float x, float y, float z, const double c[3]) {
  const double dx = static_cast<double>(x) - c[0], dy = static_cast<double>(y) - c[1],
               dz = static_cast<double>(z) - c[2];
  const double xx = dx * dx, yy = dy * dy, zz = dz * dz;
  return static_cast<float>(sqrt(xx + yy + zz));
}

// The release's depth: x · R_w2c[:,2] (the third column of the world-to-camera rotation, no translation),
// in double as glm::dot computes it, rounded to float once. Signed: the release's DD-Drop takes no |·|.
D2GS_HD float dd_drop_depth_release(float x, float y, float z, const double axis[3]) {
  const double xa = static_cast<double>(x) * axis[0], ya = static_cast<double>(y) * axis[1],
               za = static_cast<double>(z) * axis[2];
  return static_cast<float>(xa + ya + za);
}

// Min-max normalisation of v given the minimum lo and range = max − lo: (v − lo)/range, 0 where the
// range is not positive (a constant input).
D2GS_HD float minmax_normalised(float v, float lo, float range) { return range > 0.0f ? (v - lo) / range : 0.0f; }

// Layer of depth d given the tertile thresholds t1 ≤ t2: 0 near (d < t1), 1 middle (d < t2), 2 far.
D2GS_HD int depth_layer(float d, float t1, float t2) { return d < t1 ? 0 : d < t2 ? 1 : 2; }

// p_i from its normalised depth and density score (both in [0, 1]) and its layer.
D2GS_HD float dd_drop_probability(float depth_norm, float density_norm, int layer, const DdDropTerms& o) {
  double s = 0.0;
  if (o.use_depth_score) s += o.weight_depth * (1.0 - depth_norm);
  if (o.use_density_score) s += o.weight_density * density_norm;
  const double lambda = o.use_layers ? o.lambdas[layer] : 1.0;
  const double p = lambda * s * o.rate;
  return static_cast<float>(p < 0.0 ? 0.0 : 1.0 < p ? 1.0 : p);  // std::clamp(p, 0.0, 1.0), NaN kept
}

}  // namespace d2gs
