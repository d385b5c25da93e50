#pragma once
// DeviceStep (device_step.hpp) written once over a backend of render/kernels/pipeline.hpp (device memory and
// kernel_shell, or host arrays and the emulator), like the other pipelines: the model is the stage
// pipeline's own arrays, which Adam's kernel updates in place.
//
// The arithmetic is that of the stages (StagePipeline) and of the loss, statistic and Adam kernels, each
// checked on its own against the CPU (EmulatedRasterizer, SsimKernels, L1Kernel, AdamKernel, ...); the test
// ResidentStep.* checks the chaining: the emulated resident step against the same kernels called one by
// one with host arrays in between (bit for bit), and against the CPU's step.
#include <cmath>
#include <cstdint>
#include <initializer_list>
#include <utility>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/render/kernels/block.hpp"
#include "d2gs/render/kernels/pipeline.hpp"
#include "d2gs/train/kernels/densify_kernels.hpp"
#include "d2gs/train/kernels/device_step.hpp"
#include "d2gs/train/kernels/optim_pipeline.hpp"
#include "d2gs/train/kernels/per_gaussian_pipeline.hpp"
#include "d2gs/train/kernels/ssim_pipeline.hpp"
#include "d2gs/train/kernels/step_kernels.hpp"

namespace d2gs::train_kernels {

template <class Backend>
class ResidentStep final : public DeviceStep {
public:
  template <class... A>
  explicit ResidentStep(const char* name, A&&... backend_args)
      : stages_(name, std::forward<A>(backend_args)...), ssim_(stages_.backend()) {}

  const char* name() const override { return stages_.name(); }

  void set_training_views(const std::vector<Image>& images, const std::vector<Ssim<float>::Reference>& refs) override {
    if (images.size() != refs.size()) fail("resident step: {} images but {} SSIM references", images.size(), refs.size());
    views_.clear();
    views_.resize(images.size());
    for (std::size_t v = 0; v < images.size(); ++v) {
      const Image& im = images[v];
      const Ssim<float>::Reference& r = refs[v];
      const std::size_t values = static_cast<std::size_t>(im.width) * im.height * 3;
      if (im.channels != 3 || im.pixels.size() != values || r.width != im.width || r.height != im.height ||
          r.channels != 3 || r.b.size() != values || r.mu_b.size() != values || r.s_bb.size() != values)
        fail("resident step: training view {} and its SSIM reference differ in size", v);
      View& d = views_[v];
      d.width = im.width;
      d.height = im.height;
      backend().upload(d.rgb, im.pixels.data(), values);
      backend().upload(d.b, r.b.data(), values);
      backend().upload(d.mu_b, r.mu_b.data(), values);
      backend().upload(d.s_bb, r.s_bb.data(), values);
    }
  }

  void upload(const Gaussians& model, const AdamState& adam, const GradientStats& stats) override {
    model.validate();
    n_ = model.size();
    if (adam.exp_avg.size() != n_ || adam.exp_avg_sq.size() != n_ || stats.size() != n_ ||
        adam.exp_avg.sh_degree != model.sh_degree || adam.exp_avg_sq.sh_degree != model.sh_degree)
      fail("resident step: model, moments and statistics are not aligned ({}, {}, {} rows)", n_, adam.exp_avg.size(),
           stats.size());
    sh_degree_ = model.sh_degree;
    adam_step_ = adam.step;
    put(stages_.model(), model);
    put(moments1(), adam.exp_avg);
    put(moments2(), adam.exp_avg_sq);
    backend().upload(grad_sum_, stats.sums().data(), n_);
    backend().upload(grad_count_, stats.counts().data(), n_);
  }

  void download(Gaussians& model, AdamState& adam, GradientStats& stats) override {
    get(stages_.model(), model);
    get(moments1(), adam.exp_avg);
    get(moments2(), adam.exp_avg_sq);
    adam.step = adam_step_;
    std::vector<float> sums, counts;
    backend().download(sums, grad_sum_, n_);
    backend().download(counts, grad_count_, n_);
    stats.restore(std::move(sums), std::move(counts));
  }

  std::size_t size() const override { return n_; }

  ResidentLoss render_and_backward(std::size_t view, const ResidentRender& r, Rng& dropout_rng, float lambda_dssim) override {
    if (view >= views_.size()) fail("resident step: training view {} of {}", view, views_.size());
    View& gt = views_[view];
    if (r.camera.width != gt.width || r.camera.height != gt.height)
      fail("resident step: the render ({}x{}) and training view {} ({}x{}) differ in size", r.camera.width,
           r.camera.height, view, gt.width, gt.height);
    if (r.dropgaussian && r.dd_drop) fail("resident step: two opacity multipliers in one step");
    if (r.dropgaussian) {
      if (!(r.drop_rate >= 0.0 && r.drop_rate < 1.0)) fail("DropGaussian: rate {} outside [0, 1)", r.drop_rate);
      stages_.multiplier().resize(n_);
      dropout_mask_into(backend(), mask_buffers_, n_, nullptr, r.drop_rate, false, dropout_rng,
                        stages_.multiplier().data());
    }
    if (r.dd_drop) dd_drop_mask(*r.dd_drop, dropout_rng);
    const bool with_multiplier = r.dropgaussian || r.dd_drop;
    ResidentLoss loss;
    if (with_multiplier && n_ > 0) loss.drop_fraction = zeros(stages_.multiplier(), n_) / static_cast<double>(n_);
    stages_.forward_resident(n_, sh_degree_, with_multiplier, r.camera, r.stages);
    stages_.composite_resident(r.composite);
    const std::size_t values = static_cast<std::size_t>(gt.width) * gt.height * 3;
    const int count = static_cast<int>(values);
    float* rgb = stages_.image().rgb.data();
    float* grad = stages_.image_gradients().rgb.data();
    pred_.resize(values);
    ClampArgs c;
    c.n = count;
    c.rgb = rgb;
    c.clamped = pred_.data();
    c.grad = grad;
    render::kernels::launch_per_item<ClampKernel>(backend(), count, c);
    l1_loss_launch(backend(), pred_.data(), gt.rgb.data(), values, grad, 1.0f, l1_sum_);
    loss.ssim = ssim_.evaluate_on(pred_.data(), gt.b.data(), gt.mu_b.data(), gt.s_bb.data(), gt.width, gt.height, 3,
                                  grad, -lambda_dssim);
    loss.l1 = backend().read(l1_sum_, 0) / static_cast<double>(values);
    if (r.dafe) loss.dafe = dafe(view, *r.dafe, grad);
    ClampGradientArgs g;
    g.n = count;
    g.rgb = rgb;
    g.grad = grad;
    render::kernels::launch_per_item<ClampGradientKernel>(backend(), count, g);
    stages_.backward_resident(false, false);
    width_ = gt.width;
    height_ = gt.height;
    return loss;
  }

  bool gradients_finite() override {
    auto g = stages_.gradients();
    return finite({{&g.means, n_ * 3}, {&g.log_scales, n_ * 3}, {&g.quats, n_ * 4}, {&g.opacity_logits, n_},
                       {&g.sh_dc, n_ * 3}, {&g.sh_rest, rest_values()}});
  }
  bool parameters_finite() override {
    auto m = stages_.model();
    return finite({{&m.means, n_ * 3}, {&m.log_scales, n_ * 3}, {&m.quats, n_ * 4}, {&m.opacity_logits, n_}});
  }

  void add_gradient_stats() override {
    if (n_ == 0) return;
    const int n = static_cast<int>(n_);
    ndc_.resize(n_ * 2);
    Mean2dNdcArgs m;
    m.n = n;
    m.d_mean2d = stages_.mean2d_gradient().data();
    m.sx = 0.5f * static_cast<float>(width_);
    m.sy = 0.5f * static_cast<float>(height_);
    m.out = ndc_.data();
    render::kernels::launch_per_item<Mean2dNdcKernel>(backend(), n, m);
    GradientStatsArgs a;
    a.n = n;
    a.grad_mean2d_ndc = ndc_.data();
    a.radii = stages_.radii().data();
    a.sum = grad_sum_.data();
    a.count = grad_count_.data();
    render::kernels::launch_per_item<GradientStatsKernel>(backend(), n, a);
  }

  void adam(const LearningRates& lr, float means_lr, bool skip_opacity) override {
    ++adam_step_;
    const double bias1 = 1.0 - std::pow(Adam::kBeta1, static_cast<double>(adam_step_));
    const double bias2 = 1.0 - std::pow(Adam::kBeta2, static_cast<double>(adam_step_));
    auto p = stages_.model();
    auto g = stages_.gradients();
    auto m = moments1();
    auto v = moments2();
    const auto group = [&](Array<float>& param, Array<float>& grad, Array<float>& exp_avg, Array<float>& exp_avg_sq,
                           std::size_t count, double rate) {
      adam_group(backend(), param.data(), grad.data(), exp_avg.data(), exp_avg_sq.data(), count,
                 adam_scalars(rate, bias1, bias2));
    };
    group(p.means, g.means, m.means, v.means, n_ * 3, means_lr);
    group(p.sh_dc, g.sh_dc, m.sh_dc, v.sh_dc, n_ * 3, lr.sh_dc);
    group(p.sh_rest, g.sh_rest, m.sh_rest, v.sh_rest, rest_values(), lr.sh_rest);
    if (!skip_opacity) group(p.opacity_logits, g.opacity_logits, m.opacity_logits, v.opacity_logits, n_, lr.opacity);
    group(p.log_scales, g.log_scales, m.log_scales, v.log_scales, n_ * 3, lr.scales);
    group(p.quats, g.quats, m.quats, v.quats, n_ * 4, lr.quats);
  }

  Backend& backend() { return stages_.backend(); }

private:
  using Stages = render::kernels::StagePipeline<Backend>;
  template <class T>
  using Array = typename Backend::template Array<T>;

  struct View {
    int width = 0, height = 0;
    Array<float> rgb, b, mu_b, s_bb;
    Array<std::uint8_t> mask;  // DAFE's, once uploaded
    bool mask_uploaded = false;
    std::uint64_t mask_version = 0;
  };
  // Model-shaped arrays of the moments.
  struct Moments {
    Array<float> means, log_scales, quats, opacity_logits, sh_dc, sh_rest;
    typename Stages::ModelArrays arrays() { return {means, log_scales, quats, opacity_logits, sh_dc, sh_rest}; }
  };

  typename Stages::ModelArrays moments1() { return m1_.arrays(); }
  typename Stages::ModelArrays moments2() { return m2_.arrays(); }
  std::size_t rest_values() const {
    return n_ * static_cast<std::size_t>((sh_degree_ + 1) * (sh_degree_ + 1) - 1) * 3;
  }

  void put(typename Stages::ModelArrays a, const Gaussians& g) {
    backend().upload(a.means, g.means.data(), g.means.size());
    backend().upload(a.log_scales, g.log_scales.data(), g.log_scales.size());
    backend().upload(a.quats, g.quats.data(), g.quats.size());
    backend().upload(a.opacity_logits, g.opacity_logits.data(), g.opacity_logits.size());
    backend().upload(a.sh_dc, g.sh_dc.data(), g.sh_dc.size());
    backend().upload(a.sh_rest, g.sh_rest.data(), g.sh_rest.size());
  }
  void get(typename Stages::ModelArrays a, Gaussians& g) {
    g.sh_degree = sh_degree_;
    backend().download(g.means, a.means, n_ * 3);
    backend().download(g.log_scales, a.log_scales, n_ * 3);
    backend().download(g.quats, a.quats, n_ * 4);
    backend().download(g.opacity_logits, a.opacity_logits, n_);
    backend().download(g.sh_dc, a.sh_dc, n_ * 3);
    backend().download(g.sh_rest, a.sh_rest, rest_values());
  }

  // DD-Drop's probabilities from the model's means on the device and the density scores (uploaded when
  // their version changed), then the Bernoulli mask into the stages' multiplier.
  void dd_drop_mask(const ResidentDdDrop& d, Rng& rng) {
    if (!d.density || d.density->size() != n_)
      fail("DD-Drop: {} density scores for {} Gaussians", d.density ? d.density->size() : 0, n_);
    if (!density_uploaded_ || d.density_version != density_version_ || density_count_ != n_) {
      backend().upload(density_, d.density->data(), n_);
      density_uploaded_ = true;
      density_version_ = d.density_version;
      density_count_ = n_;
    }
    dd_drop_.probabilities_of(stages_.model().means.data(), density_.data(), n_, d.camera, d.options, d.iteration);
    stages_.multiplier().resize(n_);
    if (n_ > 0)
      dropout_mask_into(backend(), mask_buffers_, n_, dd_drop_.device_probabilities(), 0.0, d.options.compensate, rng,
                        stages_.multiplier().data());
  }

  // The DAFE term of `view` on pred_ against its image, weight · its gradient added to grad; the masks of
  // every view uploaded when their version changed.
  double dafe(std::size_t view, const ResidentDafe& d, float* grad) {
    if (!d.mask) fail("DAFE: no mask");
    View& v = views_[view];
    const std::size_t pixels = static_cast<std::size_t>(v.width) * v.height;
    if (d.mask->empty()) return 0.0;  // no mask yet: the CPU's term is 0 too
    if (d.mask->size() != pixels) fail("DAFE: mask has {} pixels, image {}x{}", d.mask->size(), v.width, v.height);
    if (!v.mask_uploaded || v.mask_version != d.mask_version) {
      backend().upload(v.mask, d.mask->data(), pixels);
      v.mask_uploaded = true;
      v.mask_version = d.mask_version;
    }
    return dafe_loss_launch(backend(), dafe_buffers_, pred_.data(), v.rgb.data(), v.mask.data(), v.width, v.height, 3,
                            d.form, grad, d.weight);
  }

  // The number of zeros among the first n values of `values`.
  double zeros(Array<float>& values, std::size_t n) {
    const int count = static_cast<int>(n);
    const int blocks = render::kernels::blocks_for(count);
    partials_.resize(static_cast<std::size_t>(blocks));
    ZeroCountArgs z;
    z.n = count;
    z.values = values.data();
    z.partials = partials_.data();
    backend().template launch<ZeroCountKernel>(blocks, render::kernels::kBlockThreads, z);
    sum_.resize(1);
    SumPartialsArgs s;
    s.n = blocks;
    s.partials = partials_.data();
    s.sum = sum_.data();
    backend().template launch<SumPartialsKernel>(1, render::kernels::kBlockThreads, s);
    return backend().read(sum_, 0);
  }

  struct Checked {
    Array<float>* values;
    std::size_t count;
  };
  bool finite(std::initializer_list<Checked> arrays) {
    flag_.resize(1);
    backend().zero(flag_, 1);
    for (const Checked& c : arrays) {
      if (c.count == 0) continue;
      NonFiniteArgs a;
      a.n = static_cast<int>(c.count);
      a.values = c.values->data();
      a.flag = flag_.data();
      render::kernels::launch_per_item<NonFiniteKernel>(backend(), static_cast<long long>(c.count), a);
    }
    return backend().read(flag_, 0) == 0;
  }

  Stages stages_;
  SsimPipeline<Backend> ssim_;
  DropoutMaskBuffers<Backend> mask_buffers_;
  DdDropPipeline<Backend> dd_drop_{stages_.backend()};
  DafeBuffers<Backend> dafe_buffers_;
  Array<float> density_;
  bool density_uploaded_ = false;
  std::uint64_t density_version_ = 0;
  std::size_t density_count_ = 0;
  std::vector<View> views_;
  Moments m1_, m2_;
  Array<float> grad_sum_, grad_count_, pred_, ndc_;
  Array<double> l1_sum_, partials_, sum_;
  Array<int> flag_;
  std::size_t n_ = 0;
  int sh_degree_ = 0;
  long adam_step_ = 0;
  int width_ = 0, height_ = 0;
};

}  // namespace d2gs::train_kernels
