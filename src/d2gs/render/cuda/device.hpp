#pragma once
// CUDA device discovery and the first kernels. Every function here exists in every build: without the
// CUDA backend (D2GS_HAVE_CUDA undefined) they report that no GPU is available.
#include <string>
#include <vector>

namespace d2gs::cuda {

// Number of usable CUDA devices (0 without a GPU, a driver, or the CUDA build).
int device_count();
// A one-line description of device 0, or why there is none.
std::string describe_device();
// out[i] = sigmoid(logits[i]) computed on the GPU; throws d2gs::Error when no GPU is available.
std::vector<float> sigmoid_on_device(const std::vector<float>& logits);

}  // namespace d2gs::cuda
