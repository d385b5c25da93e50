#include "d2gs/render/cpu/cpu_rasterizer.hpp"

#include <algorithm>

#include "d2gs/core/error.hpp"
#include "d2gs/core/stage_profile.hpp"
#include "d2gs/render/cpu/binning.hpp"
#include "d2gs/render/cpu/composite.hpp"
#include "d2gs/render/cpu/projection.hpp"
#include "d2gs/render/cpu/sh.hpp"
#include "d2gs/render/raster_math.hpp"

namespace d2gs::render::cpu {
namespace {

// Sizes a render's image buffers (RGB, alpha, depth: Outputs<T> or RenderOutputs) to the camera.
template <typename Images>
void size_images(Images& out, int width, int height) {
  const std::size_t pixels = static_cast<std::size_t>(std::max(width, 0)) * std::max(height, 0);
  out.width = width;
  out.height = height;
  out.rgb.resize(pixels * 3);
  out.alpha.resize(pixels);
  out.depth.resize(pixels);
}

}  // namespace

template <typename T>
const Outputs<T>& CpuRasterizerCore<T>::forward(const ModelView<T>& model, const T* opacity_multiplier,
                                                const CameraParams<T>& camera, const RenderOptions& options) {
  size_images(outputs_, camera.width, camera.height);
  forward_into(model, opacity_multiplier, camera, options, outputs_.rgb.data(), outputs_.alpha.data(),
               outputs_.depth.data());
  return outputs_;
}

template <typename T>
void CpuRasterizerCore<T>::forward_into(const ModelView<T>& model, const T* opacity_multiplier,
                                        const CameraParams<T>& camera, const RenderOptions& options, T* rgb,
                                        T* alpha, T* depth) {
  if (camera.width <= 0 || camera.height <= 0) fail("render: camera size {}x{} is empty", camera.width, camera.height);
  if (model.sh_degree < 0 || model.sh_degree > 3) fail("render: model SH degree {} is outside 0..3", model.sh_degree);
  model_ = model;
  multiplier_ = opacity_multiplier;
  camera_ = camera;
  options_ = options;
  active_degree_ = options.sh_degree < 0 ? model.sh_degree : std::min(options.sh_degree, model.sh_degree);
  for (int c = 0; c < 3; ++c) background_[c] = static_cast<T>(options.background[c]);

  {
    const profile::Scope p("render: projection");
    project_forward(model, opacity_multiplier, camera, projected_);
  }
  {
    const profile::Scope p("render: SH");
    sh_forward(model, active_degree_, camera, projected_);
  }
  const double alpha_min = options.smooth_cutoff ? kSmoothAlphaLo : kAlphaMin;
  {
    const profile::Scope p("render: binning");
    bin_gaussians(projected_, camera.width, camera.height, alpha_min, binning_);
  }
  const profile::Scope p("render: compositing");
  composite_forward(binning_, background_, options.smooth_cutoff, rgb, alpha, depth, pixels_);
}

template <typename T>
void CpuRasterizerCore<T>::backward(const T* d_rgb, const T* d_alpha, const T* d_depth,
                                    const ModelGradView<T>& grads, T* grad_mean2d_ndc) {
  const std::size_t n = model_.count;
  {
    const profile::Scope p("backward: compositing");
    composite_backward(binning_, background_, options_.smooth_cutoff, options_.alpha_clamp_pass_through, pixels_, d_rgb,
                       d_alpha, d_depth, n, isect_grads_, projected_grads_);
  }
  if (grad_mean2d_ndc) {
    const profile::Scope p("backward: NDC gradient");
    const T sx = T(0.5) * T(camera_.width), sy = T(0.5) * T(camera_.height);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i) {
      grad_mean2d_ndc[i * 2] = projected_grads_.mean2d[i * 2] * sx;
      grad_mean2d_ndc[i * 2 + 1] = projected_grads_.mean2d[i * 2 + 1] * sy;
    }
  }
  {
    const profile::Scope p("backward: projection");
    project_backward(model_, multiplier_, camera_, projected_, projected_grads_, grads);
  }
  const profile::Scope p("backward: SH");
  sh_backward(model_, active_degree_, camera_, projected_, projected_grads_.color.data(), grads);
}

template class CpuRasterizerCore<float>;
template class CpuRasterizerCore<double>;

namespace {

class CpuRasterizer final : public Rasterizer {
public:
  const char* name() const override { return "cpu"; }

  const RenderOutputs& forward(const Gaussians& model, const float* opacity_multiplier, const RenderCamera& camera,
                               const RenderOptions& options) override {
    model.validate();
    const ModelView<float> view = model_view(model);
    size_images(out_, camera.width, camera.height);
    core_.forward_into(view, opacity_multiplier, camera, options, out_.rgb.data(), out_.alpha.data(),
                       out_.depth.data());
    const auto& radii = core_.projected().radii;
    out_.radii.assign(radii.begin(), radii.begin() + static_cast<std::ptrdiff_t>(view.count));
    out_.n_intersections = core_.binning().intersections;
    n_ = view.count;
    degree_ = model.sh_degree;
    return out_;
  }

  RenderGradients& backward(const float* d_rgb, const float* d_alpha, const float* d_depth) override {
    Gaussians& g = grads_.model;
    if (g.size() != n_ || g.sh_degree != degree_) {
      g.sh_degree = degree_;
      const std::size_t K = static_cast<std::size_t>(sh_coeff_count(degree_) - 1);
      g.means.resize(n_ * 3);
      g.log_scales.resize(n_ * 3);
      g.quats.resize(n_ * 4);
      g.opacity_logits.resize(n_);
      g.sh_dc.resize(n_ * 3);
      g.sh_rest.resize(n_ * K * 3);
    }
    grads_.grad_mean2d_ndc.resize(n_ * 2);
    core_.backward(d_rgb, d_alpha, d_depth, model_grad_view(g), grads_.grad_mean2d_ndc.data());
    return grads_;
  }

private:
  CpuRasterizerCore<float> core_;
  RenderOutputs out_;
  RenderGradients grads_;
  std::size_t n_ = 0;
  int degree_ = 0;
};

}  // namespace
}  // namespace d2gs::render::cpu

namespace d2gs::render {
std::unique_ptr<Rasterizer> make_cpu_rasterizer() { return std::make_unique<cpu::CpuRasterizer>(); }
}  // namespace d2gs::render
