#pragma once
// Projection stage, forward and backward, one thread per Gaussian (gsplat's ProjectionEWA3DGSFused):
// the per-Gaussian work of cpu/projection.cpp around the shared project_gaussian() and its VJP.
#include "d2gs/render/activations.hpp"
#include "d2gs/render/kernels/block.hpp"
#include "d2gs/render/projection_math.hpp"
#include "d2gs/render/raster_math.hpp"

namespace d2gs::render::kernels {

struct ProjectionFwdArgs {
  int n = 0, tiles_x = 0, tiles_y = 0;
  const float* means = nullptr;           // N x 3
  const float* log_scales = nullptr;      // N x 3
  const float* quats = nullptr;           // N x 4
  const float* opacity_logits = nullptr;  // N
  const float* multiplier = nullptr;      // N or null (= ones)
  CameraParams<float> cam;
  float* mean2d = nullptr;   // N x 2
  float* conic = nullptr;    // N x 3
  float* depth = nullptr;    // N
  float* opacity = nullptr;  // N: sigmoid(logit) * multiplier
  int* radii = nullptr;      // N: 0 = culled (near plane, singular, or no tile of the image touched)
};

D2GS_HD void projection_fwd_thread(int i, const ProjectionFwdArgs& a) {
  const float m = a.multiplier ? a.multiplier[i] : 1.0f;
  a.opacity[i] = sigmoid(a.opacity_logits[i]) * m;
  ProjectionState<float> st;
  int radius = 0;
  float* mean2d = a.mean2d + i * 2;
  float* conic = a.conic + i * 3;
  if (project_gaussian(a.means + i * 3, a.log_scales + i * 3, a.quats + i * 4, a.cam, mean2d, conic, a.depth[i],
                       radius, st)) {
    int rect[4];
    tile_rect(mean2d[0], mean2d[1], radius, a.tiles_x, a.tiles_y, rect);
    if ((rect[2] - rect[0]) * (rect[3] - rect[1]) == 0) radius = 0;
  }
  a.radii[i] = radius;
  if (radius == 0) {
    mean2d[0] = mean2d[1] = 0.0f;
    conic[0] = conic[1] = conic[2] = 0.0f;
    a.depth[i] = 0.0f;
  }
}

using ProjectionFwdKernel = PerItemKernel<ProjectionFwdArgs, projection_fwd_thread>;

struct ProjectionBwdArgs {
  int n = 0;
  const float* means = nullptr;
  const float* log_scales = nullptr;
  const float* quats = nullptr;
  const float* opacity_logits = nullptr;
  const float* multiplier = nullptr;
  CameraParams<float> cam;
  const int* radii = nullptr;       // of the forward pass
  const float* d_mean2d = nullptr;  // N x 2: dL/d of the projected quantities
  const float* d_conic = nullptr;   // N x 3
  const float* d_depth = nullptr;   // N
  const float* d_opacity = nullptr; // N
  float* d_means = nullptr;         // assigned (the SH backward adds its view-direction term after)
  float* d_log_scales = nullptr;
  float* d_quats = nullptr;
  float* d_opacity_logits = nullptr;
};

D2GS_HD void projection_bwd_thread(int i, const ProjectionBwdArgs& a) {
  float* dm = a.d_means + i * 3;
  float* ds = a.d_log_scales + i * 3;
  float* dq = a.d_quats + i * 4;
  dm[0] = dm[1] = dm[2] = 0.0f;
  ds[0] = ds[1] = ds[2] = 0.0f;
  dq[0] = dq[1] = dq[2] = dq[3] = 0.0f;
  a.d_opacity_logits[i] = 0.0f;
  if (a.radii[i] <= 0) return;
  const float m = a.multiplier ? a.multiplier[i] : 1.0f;
  const float s = sigmoid(a.opacity_logits[i]);
  a.d_opacity_logits[i] = a.d_opacity[i] * m * s * (1.0f - s);
  // The forward's intermediate values are recomputed rather than stored (as gsplat's fused kernels).
  ProjectionState<float> st;
  float mean2d[2], conic[3], depth;
  int radius;
  project_gaussian(a.means + i * 3, a.log_scales + i * 3, a.quats + i * 4, a.cam, mean2d, conic, depth, radius, st);
  project_gaussian_vjp(a.means + i * 3, a.log_scales + i * 3, a.quats + i * 4, a.cam, st, conic, a.d_mean2d + i * 2,
                       a.d_conic + i * 3, a.d_depth[i], dm, ds, dq);
}

using ProjectionBwdKernel = PerItemKernel<ProjectionBwdArgs, projection_bwd_thread>;

}  // namespace d2gs::render::kernels
