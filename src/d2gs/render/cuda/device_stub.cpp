// Built when the CUDA backend is off: the same API reports that no GPU is available.
#include "d2gs/core/error.hpp"
#include "d2gs/render/cuda/device.hpp"
#include "d2gs/render/cuda/stages.hpp"

namespace d2gs::cuda {
int device_count() { return 0; }
std::string describe_device() { return "this d2gs was built without CUDA"; }
std::size_t device_memory_in_use() { fail("CUDA: {}", describe_device()); }
std::vector<float> sigmoid_on_device(const std::vector<float>&) { fail("CUDA: {}", describe_device()); }
ProjectionOutputs project_on_device(const std::vector<float>&, const std::vector<float>&, const std::vector<float>&,
                                    const DeviceCamera&) {
  fail("CUDA: {}", describe_device());
}
std::unique_ptr<render::kernels::StageRunner> make_device_stages() { fail("CUDA: {}", describe_device()); }
}  // namespace d2gs::cuda
