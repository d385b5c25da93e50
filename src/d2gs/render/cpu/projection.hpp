#pragma once
// Stage 1: EWA projection of every Gaussian (projection_math.hpp), and its backward pass.
#include "d2gs/render/cpu/types.hpp"

namespace d2gs::render::cpu {

// Fills mean2d, conic, depth, radii (0 = culled: behind the near plane, singular, or no tile touched)
// and opacity = sigmoid(logit) * multiplier (multiplier may be null = all ones), and keeps what the
// backward needs (state, opacity_sigmoid).
template <typename T>
void project_forward(const ModelView<T>& model, const T* opacity_multiplier, const CameraParams<T>& cam,
                     Projected<T>& out);

// Writes (assigns) d_means, d_log_scales, d_quats, d_opacity_logits for every Gaussian from the
// gradients w.r.t. mean2d, conic, depth and opacity (zero for culled Gaussians). fwd is project_forward's
// output for the same model, multiplier and camera.
template <typename T>
void project_backward(const ModelView<T>& model, const T* opacity_multiplier, const CameraParams<T>& cam,
                      const Projected<T>& fwd, const ProjectedGrads<T>& grads, const ModelGradView<T>& out);

}  // namespace d2gs::render::cpu
