// Adam, the L1, SSIM and DAFE losses, DD-Drop's probabilities, the dropout masks and the densification
// statistic and edit kernels on the GPU: the bodies of train/kernels/ through kernel_shell, their host side
// (train/kernels/*_pipeline.hpp) over device memory and CUB.
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/device_backend.cuh"
#include "d2gs/train/kernels/densify_pipeline.hpp"
#include "d2gs/train/kernels/optim.hpp"
#include "d2gs/train/kernels/optim_pipeline.hpp"
#include "d2gs/train/kernels/per_gaussian_pipeline.hpp"
#include "d2gs/train/kernels/ssim_pipeline.hpp"

namespace d2gs::train_kernels {

void device_adam_step(Gaussians& model, const Gaussians& grads, AdamState& state, const LearningRates& lr,
                      float means_lr, bool skip_opacity) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  adam_step(backend, model, grads, state, lr, means_lr, skip_opacity);
}

double device_l1_loss(const float* a, const float* b, std::size_t count, float* grad, float scale) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  return l1_loss(backend, a, b, count, grad, scale);
}

Ssim<float>::Reference device_ssim_reference(const float* b, int width, int height, int channels) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  return SsimPipeline<cuda::DeviceBackend>(backend).reference(b, width, height, channels);
}

double device_ssim(const float* a, const Ssim<float>::Reference& reference, float* grad, float grad_scale) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  return SsimPipeline<cuda::DeviceBackend>(backend).evaluate(a, reference, grad, grad_scale);
}

void device_dropgaussian_mask(std::size_t n, double rate, Rng& rng, std::vector<float>& multiplier) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  dropgaussian_mask(backend, n, rate, rng, multiplier);
}

void device_bernoulli_mask(const std::vector<float>& probabilities, Rng& rng, std::vector<float>& multiplier,
                           bool compensate) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  bernoulli_mask(backend, probabilities, rng, multiplier, compensate);
}

void device_add_gradient_stats(GradientStats& stats, const std::vector<float>& grad_mean2d_ndc,
                               const std::vector<int>& radii) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  add_gradient_stats(backend, stats, grad_mean2d_ndc, radii);
}

std::vector<float> device_dd_drop_probabilities(const Gaussians& model, const Camera& camera,
                                                const std::vector<float>& density_score, const DdDropOptions& options,
                                                int iteration) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  DdDropPipeline<cuda::DeviceBackend> pipeline(backend);
  pipeline.probabilities(model, camera, density_score, options, iteration);
  return pipeline.download();
}

void device_dd_drop_mask(const Gaussians& model, const Camera& camera, const std::vector<float>& density_score,
                         const DdDropOptions& options, int iteration, Rng& rng, std::vector<float>& multiplier,
                         std::vector<float>* probabilities) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  DdDropPipeline<cuda::DeviceBackend> pipeline(backend);
  pipeline.probabilities(model, camera, density_score, options, iteration);
  pipeline.mask(rng, multiplier, options.compensate);
  if (probabilities) *probabilities = pipeline.download();
}

double device_dafe_loss(const float* a, const float* b, int width, int height, int channels,
                        const std::vector<std::uint8_t>& mask, DafeLossForm form, float* grad, float scale) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  return dafe_loss(backend, a, b, width, height, channels, mask, form, grad, scale);
}

DensifyReport device_densify_and_prune(Gaussians& model, AdamState& adam, GradientStats& stats, float scene_extent,
                                       const DensifyOptions& options, Rng& rng) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  return DensifyPipeline<cuda::DeviceBackend>(backend).densify_and_prune(model, adam, stats, scene_extent, options,
                                                                         rng);
}

DensifyReport device_prune_by_opacity(Gaussians& model, AdamState& adam, GradientStats& stats, float min_opacity) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  return DensifyPipeline<cuda::DeviceBackend>(backend).prune_by_opacity(model, adam, stats, min_opacity);
}

void device_reset_opacity(Gaussians& model, AdamState& adam, float ceiling) {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  cuda::DeviceBackend backend;
  DensifyPipeline<cuda::DeviceBackend>(backend).reset_opacity(model, adam, ceiling);
}

}  // namespace d2gs::train_kernels
