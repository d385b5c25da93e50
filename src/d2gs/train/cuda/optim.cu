// Adam, the L1 loss, SSIM, the dropout masks and the densification statistic kernels on the GPU: the bodies of train/kernels/ through kernel_shell, the host side
// of train/kernels/optim_pipeline.hpp over device memory.
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/device_backend.cuh"
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

}  // namespace d2gs::train_kernels
