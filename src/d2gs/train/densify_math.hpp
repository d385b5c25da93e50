#pragma once
// The per-Gaussian arithmetic of adaptive density control (train/densify.cpp): the densification
// statistic (GradientStats::add), the clone/split/prune decisions, the split children and the opacity
// reset, shared unchanged by the CPU and the CUDA backend's kernels (train/kernels/densify_kernels.hpp).
// C++17, no standard library: nvcc compiles it.
#include <math.h>

#include "d2gs/render/activations.hpp"
#include "d2gs/core/host_device.hpp"

namespace d2gs {

// Gaussian i, if visible (radius > 0): sum += ‖∂L/∂mean2d (NDC)‖, count += 1.
D2GS_HD void add_gradient_stat(int i, const float* grad_mean2d_ndc, const int* radii, float* sum, float* count) {
  if (radii[i] <= 0) return;
  const float gx = grad_mean2d_ndc[2 * i], gy = grad_mean2d_ndc[2 * i + 1];
  sum[i] += sqrtf(gx * gx + gy * gy);
  count[i] += 1.0f;
}

// GradientStats::mean for one Gaussian: 0 where never visible.
D2GS_HD float gradient_stat_mean(float sum, float count) { return count > 0 ? sum / count : 0.0f; }

// Selected for densification: mean gradient ≥ threshold (NaN is not).
D2GS_HD bool densify_selected(float mean_gradient, float threshold) { return mean_gradient >= threshold; }

// exp of the largest log scale (std::max({a, b, c}): the first largest by <).
D2GS_HD float densify_max_scale(const float* log_scale) {
  float m = log_scale[0];
  if (m < log_scale[1]) m = log_scale[1];
  if (m < log_scale[2]) m = log_scale[2];
  return expf(m);
}

// A selected Gaussian is cloned when small (max scale ≤ percent_dense·extent), else split.
D2GS_HD bool densify_clones(const float* log_scale, float size_limit) {
  return densify_max_scale(log_scale) <= size_limit;
}

// Pruned: opacity below the threshold.
D2GS_HD bool densify_prunes(float opacity_logit, float min_opacity) { return sigmoid(opacity_logit) < min_opacity; }

// The log-scale decrement of split children: log(0.8·children).
D2GS_HD float split_log_shrink(int children) { return logf(0.8f * static_cast<float>(children)); }

// Rotation matrix (row-major) of the normalised quaternion (w, x, y, z).
D2GS_HD void densify_rotation(const float* q, float R[9]) {
  const float n = sqrtf(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  const float w = q[0] / n, x = q[1] / n, y = q[2] / n, z = q[3] / n;
  R[0] = 1 - 2 * (y * y + z * z); R[1] = 2 * (x * y - w * z);     R[2] = 2 * (x * z + w * y);
  R[3] = 2 * (x * y + w * z);     R[4] = 1 - 2 * (x * x + z * z); R[5] = 2 * (y * z - w * x);
  R[6] = 2 * (x * z - w * y);     R[7] = 2 * (y * z + w * x);     R[8] = 1 - 2 * (x * x + y * y);
}

// A split child of the parent (mean, log_scale, quat): mean + R(quat)·(scale ⊙ normal) with the three
// standard normals (the CPU's draws rounded to float), log_scale − shrink. Opacity, rotation and SH are
// the parent's.
D2GS_HD void split_child(const float* mean, const float* log_scale, const float* quat, const float* normal,
                         float shrink, float* child_mean, float* child_log_scale) {
  float R[9];
  densify_rotation(quat, R);
  float s[3];
  for (int d = 0; d < 3; ++d) s[d] = expf(log_scale[d]) * normal[d];
  for (int r = 0; r < 3; ++r) child_mean[r] = mean[r] + (R[r * 3] * s[0] + R[r * 3 + 1] * s[1] + R[r * 3 + 2] * s[2]);
  for (int d = 0; d < 3; ++d) child_log_scale[d] = log_scale[d] - shrink;
}

// The opacity reset of one Gaussian: its logit capped at `cap` (std::min(logit, cap): the logit unless cap
// is smaller).
D2GS_HD float reset_opacity_logit(float logit, float cap) { return cap < logit ? cap : logit; }

// One try of Rng::normal's polar method on the uniforms (u01, v01): whether it is accepted and, if so,
// its two normals (u·f first, v·f kept as the spare).
D2GS_HD bool polar_normals(double u01, double v01, double* first, double* second) {
  const double u = 2.0 * u01 - 1.0, v = 2.0 * v01 - 1.0;
  const double s = u * u + v * v;
  if (s >= 1.0 || s == 0.0) return false;
  const double f = sqrt(-2.0 * log(s) / s);
  *first = u * f;
  *second = v * f;
  return true;
}

}  // namespace d2gs
