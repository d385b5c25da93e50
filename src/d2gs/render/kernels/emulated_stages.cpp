// The stages of kernels/pipeline.hpp on the CPU: host vectors for device memory, the emulator
// (kernels/emulate.hpp) for kernel launches, a stable sort for CUB's radix sort. Compiled by the host
// compiler in every build, so CI runs the CUDA backend's kernels without a GPU.
#include "d2gs/render/kernels/host_backend.hpp"
#include "d2gs/render/kernels/pipeline.hpp"

namespace d2gs::render::kernels {

std::unique_ptr<StageRunner> make_emulated_stages(emulate::Schedule schedule) {
  const char* name = schedule == emulate::Schedule::Forward   ? "emulated"
                     : schedule == emulate::Schedule::Reverse ? "emulated, reverse order"
                                                              : "emulated, shared memory visible at syncs";
  return std::make_unique<StagePipeline<emulate::HostBackend>>(name, emulate::HostBackend{schedule});
}

}  // namespace d2gs::render::kernels
