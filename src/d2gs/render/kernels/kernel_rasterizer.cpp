#include "d2gs/render/kernels/kernel_rasterizer.hpp"

#include <algorithm>
#include <utility>

#include "d2gs/core/error.hpp"
#include "d2gs/render/cpu/cpu_rasterizer.hpp"
#include "d2gs/render/raster_math.hpp"

namespace d2gs::render::kernels {
namespace {

class KernelRasterizer final : public Rasterizer {
public:
  KernelRasterizer(std::unique_ptr<StageRunner> stages, bool fused) : stages_(std::move(stages)), fused_(fused) {
    if (!stages_) fail("render: no stages for the kernel rasterizer");
  }

  const char* name() const override { return stages_->name(); }

  const RenderOutputs& forward(const Gaussians& model, const float* opacity_multiplier, const RenderCamera& camera,
                               const RenderOptions& options) override {
    model.validate();
    if (camera.width <= 0 || camera.height <= 0) fail("render: camera size {}x{} is empty", camera.width, camera.height);
    const cpu::ModelView<float> view = cpu::model_view(model);
    StageOptions so;
    so.active_degree = options.sh_degree < 0 ? model.sh_degree : std::min(options.sh_degree, model.sh_degree);
    so.alpha_min = options.smooth_cutoff ? kSmoothAlphaLo : kAlphaMin;
    const ForwardStages& f = stages_->forward(view, opacity_multiplier, camera, so);
    CompositeOptions co;
    for (int c = 0; c < 3; ++c) co.background[c] = options.background[c];
    co.smooth_cutoff = options.smooth_cutoff;
    co.clamp_pass_through = options.alpha_clamp_pass_through;
    co.fused_multiply_add = fused_;
    const CompositeStages& image = stages_->composite(co);
    out_.width = camera.width;
    out_.height = camera.height;
    out_.rgb = image.rgb;
    out_.alpha = image.alpha;
    out_.depth = image.depth;
    out_.radii = f.radii;
    out_.n_intersections = f.isect_gaussians.size();
    n_ = view.count;
    degree_ = model.sh_degree;
    return out_;
  }

  RenderGradients& backward(const float* d_rgb, const float* d_alpha, const float* d_depth) override {
    const CompositeGrads& projected = stages_->composite_backward(d_rgb, d_alpha, d_depth);
    const BackwardStages& b = stages_->backward_from_composite();
    Gaussians& g = grads_.model;
    g.sh_degree = degree_;
    g.means = b.means;
    g.log_scales = b.log_scales;
    g.quats = b.quats;
    g.opacity_logits = b.opacity_logits;
    g.sh_dc = b.sh_dc;
    g.sh_rest = b.sh_rest;
    // The CPU backend's convention: the pixel-space gradient of mean2d times (W/2, H/2).
    const float sx = 0.5f * static_cast<float>(out_.width), sy = 0.5f * static_cast<float>(out_.height);
    grads_.grad_mean2d_ndc.resize(n_ * 2);
    for (std::size_t i = 0; i < n_; ++i) {
      grads_.grad_mean2d_ndc[i * 2] = projected.mean2d[i * 2] * sx;
      grads_.grad_mean2d_ndc[i * 2 + 1] = projected.mean2d[i * 2 + 1] * sy;
    }
    return grads_;
  }

private:
  std::unique_ptr<StageRunner> stages_;
  bool fused_;
  RenderOutputs out_;
  RenderGradients grads_;
  std::size_t n_ = 0;
  int degree_ = 0;
};

}  // namespace

std::unique_ptr<Rasterizer> make_kernel_rasterizer(std::unique_ptr<StageRunner> stages, bool fused_multiply_add) {
  return std::make_unique<KernelRasterizer>(std::move(stages), fused_multiply_add);
}

}  // namespace d2gs::render::kernels
