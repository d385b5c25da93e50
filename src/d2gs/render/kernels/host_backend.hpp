#pragma once
// Host memory and the emulator as a backend of kernels/pipeline.hpp (the CPU execution path of the
// CUDA backend's host code; cuda/device_backend.cuh is the GPU's).
#include <cstdint>
#include <cstring>
#include <vector>

#include "d2gs/render/kernels/emulate.hpp"

namespace d2gs::render::kernels::emulate {

// Host memory standing in for device memory. Fresh elements are poisoned (0xff bytes: NaN floats, -1
// ints) as cudaMalloc's are undefined, so a kernel reading what no kernel wrote shows it.
template <class T>
class HostArray {
public:
  void resize(std::size_t n) {
    if (n > values_.size()) {
      values_.resize(n);
      std::memset(static_cast<void*>(values_.data()), 0xff, n * sizeof(T));
    }
  }
  T* data() { return values_.data(); }
  const T* data() const { return values_.data(); }

private:
  std::vector<T> values_;
};

struct HostBackend {
  Schedule schedule = Schedule::Forward;

  template <class T>
  using Array = HostArray<T>;

  template <class Body, class Args>
  void launch(int blocks, int threads, const Args& args) {
    if (blocks <= 0) return;
    emulate::launch<Body>(Dim{blocks, 1}, Dim{threads, 1}, args, schedule);
  }
  template <class T>
  void upload(Array<T>& dst, const T* src, std::size_t n) {
    dst.resize(n);
    if (n) std::memcpy(static_cast<void*>(dst.data()), src, n * sizeof(T));
  }
  template <class T>
  void download(std::vector<T>& dst, const Array<T>& src, std::size_t n) {
    dst.assign(src.data(), src.data() + n);
  }
  template <class T>
  T read(const Array<T>& src, std::size_t i) {
    return src.data()[i];
  }
  template <class T>
  void zero(Array<T>& dst, std::size_t n) {
    if (n) std::memset(static_cast<void*>(dst.data()), 0, n * sizeof(T));
  }
  void sort_pairs(Array<std::uint64_t>& keys, Array<std::uint64_t>& keys_out, Array<std::int32_t>& values,
                  Array<std::int32_t>& values_out, std::size_t n, int end_bit) {
    emulate::sort_pairs(keys.data(), keys_out.data(), values.data(), values_out.data(), n, end_bit);
  }
  void synchronize() {}
};

}  // namespace d2gs::render::kernels::emulate
