#pragma once
// Device memory, kernel_shell launches and CUB's radix sort as a backend of render/kernels/pipeline.hpp
// (render/kernels/host_backend.hpp is the emulator's). Include from .cu files only.
#include <cub/device/device_radix_sort.cuh>

#include <cstdint>
#include <utility>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/render/cuda/device_block.cuh"

namespace d2gs::cuda {

inline void check(cudaError_t status, const char* what) {
  if (status != cudaSuccess) fail("CUDA: {} failed: {}", what, cudaGetErrorString(status));
}

// Device memory that only grows; contents are not kept across a resize.
template <class T>
class DeviceArray {
public:
  DeviceArray() = default;
  DeviceArray(DeviceArray&& other) noexcept : ptr_(other.ptr_), capacity_(other.capacity_) {
    other.ptr_ = nullptr;
    other.capacity_ = 0;
  }
  DeviceArray& operator=(DeviceArray&& other) noexcept {
    std::swap(ptr_, other.ptr_);
    std::swap(capacity_, other.capacity_);
    return *this;
  }
  DeviceArray(const DeviceArray&) = delete;
  DeviceArray& operator=(const DeviceArray&) = delete;
  ~DeviceArray() {
    if (ptr_) cudaFree(ptr_);
  }
  void resize(std::size_t n) {
    if (n <= capacity_) return;
    if (ptr_) cudaFree(ptr_);
    ptr_ = nullptr;
    capacity_ = 0;
    check(cudaMalloc(&ptr_, sizeof(T) * n), "cudaMalloc");
    capacity_ = n;
  }
  T* data() { return ptr_; }
  const T* data() const { return ptr_; }

private:
  T* ptr_ = nullptr;
  std::size_t capacity_ = 0;
};

struct DeviceBackend {
  template <class T>
  using Array = DeviceArray<T>;
  DeviceArray<unsigned char> sort_temp;

  template <class Body, class Args>
  void launch(int blocks, int threads, const Args& args) {
    if (blocks <= 0) return;
    kernel_shell<Body, Args><<<blocks, threads>>>(args);
    check(cudaGetLastError(), "kernel launch");
  }
  template <class T>
  void upload(Array<T>& dst, const T* src, std::size_t n) {
    dst.resize(n);
    if (n) check(cudaMemcpy(dst.data(), src, n * sizeof(T), cudaMemcpyHostToDevice), "cudaMemcpy");
  }
  template <class T>
  void download(std::vector<T>& dst, const Array<T>& src, std::size_t n) {
    dst.resize(n);
    if (n) check(cudaMemcpy(dst.data(), src.data(), n * sizeof(T), cudaMemcpyDeviceToHost), "cudaMemcpy");
  }
  template <class T>
  T read(const Array<T>& src, std::size_t i) {
    T value{};
    check(cudaMemcpy(&value, src.data() + i, sizeof(T), cudaMemcpyDeviceToHost), "cudaMemcpy");
    return value;
  }
  template <class T>
  void zero(Array<T>& dst, std::size_t n) {
    if (n) check(cudaMemset(dst.data(), 0, n * sizeof(T)), "cudaMemset");
  }
  void sort_pairs(Array<std::uint64_t>& keys, Array<std::uint64_t>& keys_out, Array<std::int32_t>& values,
                  Array<std::int32_t>& values_out, std::size_t n, int end_bit) {
    if (n == 0) return;
    std::size_t bytes = 0;
    check(cub::DeviceRadixSort::SortPairs(nullptr, bytes, keys.data(), keys_out.data(), values.data(),
                                          values_out.data(), static_cast<int>(n), 0, end_bit),
          "cub::DeviceRadixSort::SortPairs (size)");
    sort_temp.resize(bytes);
    check(cub::DeviceRadixSort::SortPairs(sort_temp.data(), bytes, keys.data(), keys_out.data(), values.data(),
                                          values_out.data(), static_cast<int>(n), 0, end_bit),
          "cub::DeviceRadixSort::SortPairs");
  }
  void synchronize() { check(cudaDeviceSynchronize(), "cudaDeviceSynchronize"); }
};

}  // namespace d2gs::cuda
