// Built when the CUDA backend is off: the GPU versions of the Adam, L1, SSIM, DAFE, DD-Drop, dropout and
// densification kernels report that there is no GPU.
#include "d2gs/core/error.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/train/kernels/device_step.hpp"
#include "d2gs/train/kernels/optim.hpp"

namespace d2gs::train_kernels {

void device_adam_step(Gaussians&, const Gaussians&, AdamState&, const LearningRates&, float, bool) {
  fail("CUDA: {}", cuda::describe_device());
}
double device_l1_loss(const float*, const float*, std::size_t, float*, float) {
  fail("CUDA: {}", cuda::describe_device());
}

Ssim<float>::Reference device_ssim_reference(const float*, int, int, int) {
  fail("CUDA: {}", cuda::describe_device());
}
double device_ssim(const float*, const Ssim<float>::Reference&, float*, float) {
  fail("CUDA: {}", cuda::describe_device());
}

void device_dropgaussian_mask(std::size_t, double, Rng&, std::vector<float>&) {
  fail("CUDA: {}", cuda::describe_device());
}
void device_bernoulli_mask(const std::vector<float>&, Rng&, std::vector<float>&, bool) {
  fail("CUDA: {}", cuda::describe_device());
}
void device_add_gradient_stats(GradientStats&, const std::vector<float>&, const std::vector<int>&) {
  fail("CUDA: {}", cuda::describe_device());
}

std::vector<float> device_dd_drop_probabilities(const Gaussians&, const Camera&, const std::vector<float>&,
                                                const DdDropOptions&, int) {
  fail("CUDA: {}", cuda::describe_device());
}
void device_dd_drop_mask(const Gaussians&, const Camera&, const std::vector<float>&, const DdDropOptions&, int, Rng&,
                         std::vector<float>&, std::vector<float>*) {
  fail("CUDA: {}", cuda::describe_device());
}
double device_dafe_loss(const float*, const float*, int, int, int, const std::vector<std::uint8_t>&, DafeLossForm,
                        float*, float) {
  fail("CUDA: {}", cuda::describe_device());
}

DensifyReport device_densify_and_prune(Gaussians&, AdamState&, GradientStats&, float, const DensifyOptions&, Rng&) {
  fail("CUDA: {}", cuda::describe_device());
}
DensifyReport device_prune_by_opacity(Gaussians&, AdamState&, GradientStats&, float) {
  fail("CUDA: {}", cuda::describe_device());
}
void device_reset_opacity(Gaussians&, AdamState&, float) { fail("CUDA: {}", cuda::describe_device()); }

}  // namespace d2gs::train_kernels

namespace d2gs::train_kernels {

std::unique_ptr<DeviceStep> make_device_step() { fail("CUDA: {}", cuda::describe_device()); }

}  // namespace d2gs::train_kernels
