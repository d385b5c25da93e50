#include "d2gs/render/cuda/device.hpp"

#include <cuda_runtime.h>

#include "d2gs/core/error.hpp"
#include "d2gs/render/activations.hpp"

namespace d2gs::cuda {
namespace {

__global__ void sigmoid_kernel(const float* __restrict__ in, float* __restrict__ out, int n) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) out[i] = sigmoid(in[i]);  // the same inline function the CPU backend calls
}

void check(cudaError_t status, const char* what) {
  if (status != cudaSuccess) fail("CUDA: {} failed: {}", what, cudaGetErrorString(status));
}

}  // namespace

int device_count() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();
    return 0;
  }
  return count;
}

std::string describe_device() {
  int count = 0;
  const cudaError_t status = cudaGetDeviceCount(&count);
  if (status != cudaSuccess) return std::string("no CUDA device: ") + cudaGetErrorString(status);
  if (count == 0) return "no CUDA device";
  cudaDeviceProp prop{};
  if (cudaGetDeviceProperties(&prop, 0) != cudaSuccess) return "CUDA device 0: properties unavailable";
  return fmt::format("{} (sm_{}{}, {:.1f} GiB)", prop.name, prop.major, prop.minor,
                     static_cast<double>(prop.totalGlobalMem) / (1024.0 * 1024.0 * 1024.0));
}

std::vector<float> sigmoid_on_device(const std::vector<float>& logits) {
  if (device_count() == 0) fail("CUDA: {}", describe_device());
  const int n = static_cast<int>(logits.size());
  std::vector<float> out(logits.size());
  if (n == 0) return out;
  float* d_in = nullptr;
  float* d_out = nullptr;
  check(cudaMalloc(&d_in, sizeof(float) * n), "cudaMalloc");
  check(cudaMalloc(&d_out, sizeof(float) * n), "cudaMalloc");
  check(cudaMemcpy(d_in, logits.data(), sizeof(float) * n, cudaMemcpyHostToDevice), "cudaMemcpy");
  sigmoid_kernel<<<(n + 255) / 256, 256>>>(d_in, d_out, n);
  check(cudaGetLastError(), "sigmoid kernel launch");
  check(cudaMemcpy(out.data(), d_out, sizeof(float) * n, cudaMemcpyDeviceToHost), "cudaMemcpy");
  cudaFree(d_in);
  cudaFree(d_out);
  return out;
}

}  // namespace d2gs::cuda
