// Adam, the L1, SSIM and DAFE losses, DD-Drop's probabilities, the dropout masks and the densification
// statistic and edit kernels through the CPU emulator (every build; CI runs them without a GPU).
#include "d2gs/render/kernels/host_backend.hpp"
#include "d2gs/train/kernels/densify_pipeline.hpp"
#include "d2gs/train/kernels/optim.hpp"
#include "d2gs/train/kernels/optim_pipeline.hpp"
#include "d2gs/train/kernels/per_gaussian_pipeline.hpp"
#include "d2gs/train/kernels/ssim_pipeline.hpp"

namespace d2gs::train_kernels {

void emulated_adam_step(Gaussians& model, const Gaussians& grads, AdamState& state, const LearningRates& lr,
                        float means_lr, bool skip_opacity, render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  adam_step(backend, model, grads, state, lr, means_lr, skip_opacity);
}

double emulated_l1_loss(const float* a, const float* b, std::size_t count, float* grad, float scale,
                        render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  return l1_loss(backend, a, b, count, grad, scale);
}

Ssim<float>::Reference emulated_ssim_reference(const float* b, int width, int height, int channels,
                                               render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  return SsimPipeline(backend).reference(b, width, height, channels);
}

double emulated_ssim(const float* a, const Ssim<float>::Reference& reference, float* grad, float grad_scale,
                     render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  return SsimPipeline(backend).evaluate(a, reference, grad, grad_scale);
}

void emulated_dropgaussian_mask(std::size_t n, double rate, Rng& rng, std::vector<float>& multiplier,
                                render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  dropgaussian_mask(backend, n, rate, rng, multiplier);
}

void emulated_bernoulli_mask(const std::vector<float>& probabilities, Rng& rng, std::vector<float>& multiplier,
                             bool compensate, render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  bernoulli_mask(backend, probabilities, rng, multiplier, compensate);
}

void emulated_add_gradient_stats(GradientStats& stats, const std::vector<float>& grad_mean2d_ndc,
                                 const std::vector<int>& radii, render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  add_gradient_stats(backend, stats, grad_mean2d_ndc, radii);
}

std::vector<float> emulated_dd_drop_probabilities(const Gaussians& model, const Camera& camera,
                                                  const std::vector<float>& density_score,
                                                  const DdDropOptions& options, int iteration,
                                                  render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  DdDropPipeline pipeline(backend);
  pipeline.probabilities(model, camera, density_score, options, iteration);
  return pipeline.download();
}

void emulated_dd_drop_mask(const Gaussians& model, const Camera& camera, const std::vector<float>& density_score,
                           const DdDropOptions& options, int iteration, Rng& rng, std::vector<float>& multiplier,
                           std::vector<float>* probabilities, render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  DdDropPipeline pipeline(backend);
  pipeline.probabilities(model, camera, density_score, options, iteration);
  pipeline.mask(rng, multiplier, options.compensate);
  if (probabilities) *probabilities = pipeline.download();
}

double emulated_dafe_loss(const float* a, const float* b, int width, int height, int channels,
                          const std::vector<std::uint8_t>& mask, DafeLossForm form, float* grad, float scale,
                          render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  return dafe_loss(backend, a, b, width, height, channels, mask, form, grad, scale);
}

DensifyReport emulated_densify_and_prune(Gaussians& model, AdamState& adam, GradientStats& stats, float scene_extent,
                                         const DensifyOptions& options, Rng& rng,
                                         render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  return DensifyPipeline(backend).densify_and_prune(model, adam, stats, scene_extent, options, rng);
}

DensifyReport emulated_prune_by_opacity(Gaussians& model, AdamState& adam, GradientStats& stats, float min_opacity,
                                        render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  return DensifyPipeline(backend).prune_by_opacity(model, adam, stats, min_opacity);
}

void emulated_reset_opacity(Gaussians& model, AdamState& adam, float ceiling,
                            render::kernels::emulate::Schedule schedule) {
  render::kernels::emulate::HostBackend backend{schedule};
  DensifyPipeline(backend).reset_opacity(model, adam, ceiling);
}

}  // namespace d2gs::train_kernels
