// The device-resident training step (resident_step.hpp) on the CPU: host arrays for device memory, the
// emulator for kernel launches. Compiled like the other emulated kernels (no contraction of a*b+c, as the
// GPU's -fmad=false), so CI runs the CUDA backend's whole step without a GPU.
#include "d2gs/render/kernels/host_backend.hpp"
#include "d2gs/train/kernels/resident_step.hpp"

namespace d2gs::train_kernels {

std::unique_ptr<DeviceStep> make_emulated_step(render::kernels::emulate::Schedule schedule) {
  return std::make_unique<ResidentStep<render::kernels::emulate::HostBackend>>(
      "emulated", render::kernels::emulate::HostBackend{schedule});
}

}  // namespace d2gs::train_kernels
