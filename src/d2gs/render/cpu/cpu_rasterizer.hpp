#pragma once
// The CPU backend: the four stages chained, with every buffer owned here and reused. Templated on the
// scalar type: float is the renderer behind make_cpu_rasterizer(), double runs the gradient checks.
#include <vector>

#include "d2gs/render/cpu/types.hpp"
#include "d2gs/render/rasterizer.hpp"

namespace d2gs::render::cpu {

// Float views of a model's attribute arrays, and of a model-shaped gradient holder (sized like the model).
inline ModelView<float> model_view(const Gaussians& model) {
  ModelView<float> view;
  view.count = model.size();
  view.sh_degree = model.sh_degree;
  view.means = model.means.data();
  view.log_scales = model.log_scales.data();
  view.quats = model.quats.data();
  view.opacity_logits = model.opacity_logits.data();
  view.sh_dc = model.sh_dc.data();
  view.sh_rest = model.sh_rest.data();
  return view;
}
inline ModelGradView<float> model_grad_view(Gaussians& grads) {
  return {grads.means.data(),          grads.log_scales.data(), grads.quats.data(),
          grads.opacity_logits.data(), grads.sh_dc.data(),      grads.sh_rest.data()};
}

template <typename T>
struct Outputs {
  int width = 0, height = 0;
  std::vector<T> rgb, alpha, depth;  // H*W*3, H*W, H*W
};

template <typename T>
class CpuRasterizerCore {
public:
  // The model and the multiplier must stay alive and unchanged until backward().
  const Outputs<T>& forward(const ModelView<T>& model, const T* opacity_multiplier, const CameraParams<T>& camera,
                            const RenderOptions& options);
  // The same, writing the images into caller buffers (H*W*3, H*W, H*W; any may be null).
  void forward_into(const ModelView<T>& model, const T* opacity_multiplier, const CameraParams<T>& camera,
                    const RenderOptions& options, T* rgb, T* alpha, T* depth);
  // Writes every gradient array of `grads` (model layout) and grad_mean2d_ndc (N x 2, may be null).
  void backward(const T* d_rgb, const T* d_alpha, const T* d_depth, const ModelGradView<T>& grads,
                T* grad_mean2d_ndc);

  const Projected<T>& projected() const { return projected_; }
  const Binning<T>& binning() const { return binning_; }
  const ProjectedGrads<T>& projected_grads() const { return projected_grads_; }

private:
  ModelView<T> model_{};
  const T* multiplier_ = nullptr;
  CameraParams<T> camera_{};
  RenderOptions options_{};
  int active_degree_ = 0;
  T background_[3] = {0, 0, 0};
  Projected<T> projected_;
  Binning<T> binning_;
  PixelState<T> pixels_;
  Outputs<T> outputs_;
  ProjectedGrads<T> projected_grads_;
  std::vector<T> isect_grads_;
};

extern template class CpuRasterizerCore<float>;
extern template class CpuRasterizerCore<double>;

}  // namespace d2gs::render::cpu
