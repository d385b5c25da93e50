#include "d2gs/render/cuda/device.hpp"

#include <cuda_runtime.h>

#include "d2gs/core/error.hpp"
#include "d2gs/render/activations.hpp"
#include "d2gs/render/projection_math.hpp"

namespace d2gs::cuda {
namespace {

__global__ void sigmoid_kernel(const float* __restrict__ in, float* __restrict__ out, int n) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) out[i] = sigmoid(in[i]);  // the same inline function the CPU backend calls
}

__global__ void project_kernel(const float* __restrict__ means, const float* __restrict__ log_scales,
                               const float* __restrict__ quats, render::CameraParams<float> cam, int n,
                               float* mean2d, float* conic, float* depth, int* radii) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  render::ProjectionState<float> st;
  float m2[2] = {0, 0}, cn[3] = {0, 0, 0}, z = 0;
  int r = 0;
  if (!render::project_gaussian(means + 3 * i, log_scales + 3 * i, quats + 4 * i, cam, m2, cn, z, r, st)) r = 0;
  mean2d[2 * i] = m2[0];
  mean2d[2 * i + 1] = m2[1];
  for (int k = 0; k < 3; ++k) conic[3 * i + k] = cn[k];
  depth[i] = z;
  radii[i] = r;
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

std::size_t device_memory_in_use() {
  if (device_count() == 0) fail("CUDA: {}", describe_device());
  std::size_t free = 0, total = 0;
  check(cudaMemGetInfo(&free, &total), "cudaMemGetInfo");
  return total - free;
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

template <typename T>
struct DeviceBuffer {
  T* ptr = nullptr;
  explicit DeviceBuffer(std::size_t n) { check(cudaMalloc(&ptr, sizeof(T) * (n ? n : 1)), "cudaMalloc"); }
  ~DeviceBuffer() { cudaFree(ptr); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
};

ProjectionOutputs project_on_device(const std::vector<float>& means, const std::vector<float>& log_scales,
                                    const std::vector<float>& quats, const DeviceCamera& camera) {
  if (device_count() == 0) fail("CUDA: {}", describe_device());
  const std::size_t n = means.size() / 3;
  if (log_scales.size() != 3 * n || quats.size() != 4 * n) fail("CUDA projection: attribute sizes disagree");
  render::CameraParams<float> cam;
  cam.width = camera.width;
  cam.height = camera.height;
  for (int k = 0; k < 9; ++k) cam.R[k] = camera.R[k];
  for (int k = 0; k < 3; ++k) {
    cam.t[k] = camera.t[k];
    cam.campos[k] = camera.campos[k];
  }
  cam.fx = camera.fx;
  cam.fy = camera.fy;
  cam.cx = camera.cx;
  cam.cy = camera.cy;
  render::set_jacobian_limits(cam);
  ProjectionOutputs out;
  out.mean2d.resize(2 * n);
  out.conic.resize(3 * n);
  out.depth.resize(n);
  out.radii.resize(n);
  if (n == 0) return out;
  DeviceBuffer<float> d_means(3 * n), d_scales(3 * n), d_quats(4 * n), d_mean2d(2 * n), d_conic(3 * n), d_depth(n);
  DeviceBuffer<int> d_radii(n);
  check(cudaMemcpy(d_means.ptr, means.data(), sizeof(float) * 3 * n, cudaMemcpyHostToDevice), "cudaMemcpy");
  check(cudaMemcpy(d_scales.ptr, log_scales.data(), sizeof(float) * 3 * n, cudaMemcpyHostToDevice), "cudaMemcpy");
  check(cudaMemcpy(d_quats.ptr, quats.data(), sizeof(float) * 4 * n, cudaMemcpyHostToDevice), "cudaMemcpy");
  const int blocks = static_cast<int>((n + 255) / 256);
  project_kernel<<<blocks, 256>>>(d_means.ptr, d_scales.ptr, d_quats.ptr, cam, static_cast<int>(n), d_mean2d.ptr,
                                  d_conic.ptr, d_depth.ptr, d_radii.ptr);
  check(cudaGetLastError(), "projection kernel launch");
  check(cudaMemcpy(out.mean2d.data(), d_mean2d.ptr, sizeof(float) * 2 * n, cudaMemcpyDeviceToHost), "cudaMemcpy");
  check(cudaMemcpy(out.conic.data(), d_conic.ptr, sizeof(float) * 3 * n, cudaMemcpyDeviceToHost), "cudaMemcpy");
  check(cudaMemcpy(out.depth.data(), d_depth.ptr, sizeof(float) * n, cudaMemcpyDeviceToHost), "cudaMemcpy");
  check(cudaMemcpy(out.radii.data(), d_radii.ptr, sizeof(int) * n, cudaMemcpyDeviceToHost), "cudaMemcpy");
  return out;
}

}  // namespace d2gs::cuda
