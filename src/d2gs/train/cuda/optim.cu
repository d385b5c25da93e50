// Adam, the L1 loss and SSIM kernels on the GPU: the bodies of train/kernels/ through kernel_shell, the host side
// of train/kernels/optim_pipeline.hpp over device memory.
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/device_backend.cuh"
#include "d2gs/train/kernels/optim.hpp"
#include "d2gs/train/kernels/optim_pipeline.hpp"
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

}  // namespace d2gs::train_kernels
