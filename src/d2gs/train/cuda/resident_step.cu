// The device-resident training step (train/kernels/resident_step.hpp) on the GPU: device memory,
// kernel_shell launches, CUB's sort.
#include "d2gs/core/error.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/device_backend.cuh"
#include "d2gs/train/kernels/resident_step.hpp"

namespace d2gs::train_kernels {

std::unique_ptr<DeviceStep> make_device_step() {
  if (cuda::device_count() == 0) fail("CUDA: {}", cuda::describe_device());
  return std::make_unique<ResidentStep<cuda::DeviceBackend>>("cuda");
}

}  // namespace d2gs::train_kernels
