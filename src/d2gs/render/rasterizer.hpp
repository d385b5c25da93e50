#pragma once
// The differentiable rasterizer: backend interface (docs/rendering.md).
//
//   auto rasterizer = d2gs::render::make_cpu_rasterizer();
//   const RenderOutputs& out = rasterizer->forward(model, dropout_mask_or_null, camera, options);
//   RenderGradients& g = rasterizer->backward(dL_drgb, dL_dalpha, dL_ddepth);
//
// A rasterizer object owns all of its workspace and reuses it from one call to the next, so a training
// loop allocates nothing after the first iterations. forward() results stay valid until the next
// forward(); backward() refers to the model, multiplier and camera of the last forward(), which must
// still be alive and unchanged.
#include <cstddef>
#include <memory>
#include <vector>

#include <glm/glm.hpp>

#include "d2gs/model/gaussians.hpp"
#include "d2gs/render/projection_math.hpp"
#include "d2gs/scene/camera.hpp"

namespace d2gs::render {

// Camera in the kernels' form, built from a d2gs::Camera (OpenCV axes, pixel centres at +0.5).
template <typename T>
CameraParams<T> make_camera_params(const Camera& camera) {
  CameraParams<T> p;
  p.width = camera.width;
  p.height = camera.height;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) p.R[r * 3 + c] = static_cast<T>(camera.R_world_to_cam[c][r]);  // glm: [col][row]
    p.t[r] = static_cast<T>(camera.t_world_to_cam[r]);
  }
  const glm::dvec3 centre = camera.center_world();
  for (int k = 0; k < 3; ++k) p.campos[k] = static_cast<T>(centre[k]);
  p.fx = static_cast<T>(camera.fx);
  p.fy = static_cast<T>(camera.fy);
  p.cx = static_cast<T>(camera.cx);
  p.cy = static_cast<T>(camera.cy);
  set_jacobian_limits(p);
  return p;
}
using RenderCamera = CameraParams<float>;
inline RenderCamera make_render_camera(const Camera& camera) { return make_camera_params<float>(camera); }

struct RenderOptions {
  glm::vec3 background{0.0f};  // added with the final transmittance
  int sh_degree = -1;          // active SH degree (<= the model's); -1 = the model's degree
  // Gradient checks only: replaces the hard alpha >= 1/255 test and the early stop by a smooth cutoff
  // (raster_math.hpp) so that finite differences are meaningful. Off for rendering and training.
  bool smooth_cutoff = false;
  // The gradient through alpha = min(0.99, o G) (raster_math.hpp, alpha_clamp_gradient_passes): false =
  // the derivative of the clamp, zero where it is active; true = as if unclamped, the rule of the
  // original 3DGS rasterizer (backward.cu) that DropGaussian and D²GS inherit. Backward only.
  bool alpha_clamp_pass_through = false;
};

struct RenderOutputs {
  int width = 0, height = 0;
  std::vector<float> rgb;    // H x W x 3, row-major, interleaved; not clamped (the loss clamps)
  std::vector<float> alpha;  // H x W, 1 - final transmittance
  // H x W: expected view-space depth sum_i alpha_i T_i z_i, NOT divided by alpha (0 where empty);
  // divide by alpha for a normalised depth.
  std::vector<float> depth;
  std::vector<int> radii;    // N: screen radius in pixels; > 0 = visible (densification statistics)
  std::size_t n_intersections = 0;  // (tile, Gaussian) pairs composited; a cost measure
  bool visible(std::size_t i) const { return radii[i] > 0; }
};

struct RenderGradients {
  Gaussians model;                     // d loss / d parameters, same shape as the model
  std::vector<float> grad_mean2d_ndc;  // N x 2: d loss / d mean2d in NDC units (pixel grad * 0.5 W, 0.5 H)
};

class Rasterizer {
public:
  virtual ~Rasterizer() = default;
  virtual const char* name() const = 0;
  // opacity_multiplier: N values (dropout mask) or null = all ones; effective opacity is
  // sigmoid(logit) * multiplier in forward and backward.
  virtual const RenderOutputs& forward(const Gaussians& model, const float* opacity_multiplier,
                                       const RenderCamera& camera, const RenderOptions& options) = 0;
  // Gradients of the loss w.r.t. the outputs of the last forward(): H x W x 3, H x W, H x W; any may be
  // null (= zero). The caller may add to them (a loss term on the parameters themselves) until the next call.
  virtual RenderGradients& backward(const float* d_rgb, const float* d_alpha, const float* d_depth) = 0;
};

// The CPU reference backend (OpenMP over tiles; deterministic whatever the thread count).
std::unique_ptr<Rasterizer> make_cpu_rasterizer();

}  // namespace d2gs::render
