#pragma once
// CUDA device discovery and the first kernels. Every function here exists in every build: without the
// CUDA backend (D2GS_HAVE_CUDA undefined) they report that no GPU is available.
#include <cstddef>
#include <string>
#include <vector>

namespace d2gs::cuda {

// Number of usable CUDA devices (0 without a GPU, a driver, or the CUDA build).
int device_count();
// A one-line description of device 0, or why there is none.
std::string describe_device();
// Bytes of device 0's memory in use by every process (cudaMemGetInfo: total - free); throws d2gs::Error
// when no GPU is available.
std::size_t device_memory_in_use();
// out[i] = sigmoid(logits[i]) computed on the GPU; throws d2gs::Error when no GPU is available.
std::vector<float> sigmoid_on_device(const std::vector<float>& logits);

// The projection stage on the GPU, calling the same project_gaussian() (render/projection_math.hpp) as
// the CPU backend: per Gaussian mean2d (2), conic (3), depth and radius (0 = culled). `camera` is a
// render::CameraParams<float> passed as its 25 floats + 2 ints through this plain struct.
struct ProjectionOutputs {
  std::vector<float> mean2d, conic, depth;
  std::vector<int> radii;
};
struct DeviceCamera {
  int width = 0, height = 0;
  float R[9] = {}, t[3] = {}, campos[3] = {}, fx = 0, fy = 0, cx = 0, cy = 0;
};
ProjectionOutputs project_on_device(const std::vector<float>& means, const std::vector<float>& log_scales,
                                    const std::vector<float>& quats, const DeviceCamera& camera);

}  // namespace d2gs::cuda
