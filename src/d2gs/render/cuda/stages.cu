// The stages of render/kernels/pipeline.hpp on the GPU: device memory, kernel_shell<<<>>> launches of the
// kernel bodies that the emulator runs in CI, and cub::DeviceRadixSort for the (tile | depth) keys.
#include "d2gs/render/cuda/stages.hpp"

#include "d2gs/core/error.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/device_backend.cuh"
#include "d2gs/render/kernels/pipeline.hpp"

namespace d2gs::cuda {

std::unique_ptr<render::kernels::StageRunner> make_device_stages() {
  if (device_count() == 0) fail("CUDA: {}", describe_device());
  return std::make_unique<render::kernels::StagePipeline<DeviceBackend>>("cuda");
}

}  // namespace d2gs::cuda
