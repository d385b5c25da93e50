#pragma once
// The GPU side of the kernel shape (render/kernels/block.hpp): DeviceBlock answers a kernel body's
// requests with the CUDA built-ins, and kernel_shell is the one __global__ function every kernel body is
// launched through. The CPU emulator (render/kernels/emulate.hpp) answers the same requests on the host.
#include <cuda_runtime.h>
#include <string.h>

#include <type_traits>

#include "d2gs/render/kernels/block.hpp"

namespace d2gs::cuda {

using render::kernels::Thread;

// Members are __host__ __device__ with device-only bodies, so that the D2GS_HD kernel bodies instantiated
// for DeviceBlock compile in nvcc's host pass too (they are only ever called on the device).
struct DeviceBlock {
  template <class T>
  struct Reg {
    T value;
    D2GS_HD T& operator[](const Thread&) { return value; }
    D2GS_HD const T& operator[](const Thread&) const { return value; }
  };
  template <class T>
  D2GS_HD Reg<T> reg() const {
    Reg<T> r{};
    return r;
  }
  template <class F>
  D2GS_HD void threads(F&& f) const {
#if defined(__CUDA_ARCH__)
    Thread t;
    t.x = static_cast<int>(threadIdx.x);
    t.y = static_cast<int>(threadIdx.y);
    t.block_x = static_cast<int>(blockIdx.x);
    t.block_y = static_cast<int>(blockIdx.y);
    t.dim_x = static_cast<int>(blockDim.x);
    t.dim_y = static_cast<int>(blockDim.y);
    f(t);
#else
    (void)f;
#endif
  }
  D2GS_HD void sync() const {
#if defined(__CUDA_ARCH__)
    __syncthreads();
#endif
  }
  D2GS_HD render::kernels::Dim block_idx() const {
    render::kernels::Dim d;
#if defined(__CUDA_ARCH__)
    d.x = static_cast<int>(blockIdx.x);
    d.y = static_cast<int>(blockIdx.y);
#endif
    return d;
  }
  template <class T>
  D2GS_HD int sync_count(const Reg<T>& pred) const {
#if defined(__CUDA_ARCH__)
    return __syncthreads_count(pred.value != T{} ? 1 : 0);
#else
    return (void)pred, 0;
#endif
  }
  // Scalars go through the built-in shuffles; a struct (the reductions' gradient records) one 32-bit
  // word at a time, every word from the same source lane.
  template <class T, class Op>
  D2GS_HD static T shuffle_words(const T& v, Op op) {
    if constexpr (std::is_arithmetic_v<T>) {
      return op(v);
    } else {
      static_assert(sizeof(T) % 4 == 0 && std::is_trivially_copyable_v<T>, "shuffle of a struct of 32-bit words");
      unsigned words[sizeof(T) / 4];
      memcpy(words, &v, sizeof(T));
      for (unsigned& w : words) w = op(w);
      T out;
      memcpy(&out, words, sizeof(T));
      return out;
    }
  }
  template <class T>
  D2GS_HD void shfl_up(Reg<T>& dst, const Reg<T>& src, int delta) const {
#if defined(__CUDA_ARCH__)
    dst.value = shuffle_words(src.value, [delta](auto w) { return __shfl_up_sync(0xffffffffu, w, static_cast<unsigned>(delta)); });
#else
    (void)dst, (void)src, (void)delta;
#endif
  }
  template <class T>
  D2GS_HD void shfl_down(Reg<T>& dst, const Reg<T>& src, int delta) const {
#if defined(__CUDA_ARCH__)
    dst.value = shuffle_words(src.value, [delta](auto w) { return __shfl_down_sync(0xffffffffu, w, static_cast<unsigned>(delta)); });
#else
    (void)dst, (void)src, (void)delta;
#endif
  }
  template <class T>
  D2GS_HD void warp_any(Reg<int>& dst, const Reg<T>& src) const {
#if defined(__CUDA_ARCH__)
    dst.value = __any_sync(0xffffffffu, src.value != T{}) ? 1 : 0;
#else
    (void)dst, (void)src;
#endif
  }
  // `active` is warp-uniform (a warp_any result), so the whole warp takes the shuffle or skips it.
  template <class T>
  D2GS_HD void shfl_down_if(const Reg<int>& active, Reg<T>& dst, const Reg<T>& src, int delta) const {
#if defined(__CUDA_ARCH__)
    if (active.value)
      dst.value = shuffle_words(src.value, [delta](auto w) { return __shfl_down_sync(0xffffffffu, w, static_cast<unsigned>(delta)); });
#else
    (void)active, (void)dst, (void)src, (void)delta;
#endif
  }
  template <class T>
  D2GS_HD void shfl_xor(Reg<T>& dst, const Reg<T>& src, int mask) const {
#if defined(__CUDA_ARCH__)
    dst.value = shuffle_words(src.value, [mask](auto w) { return __shfl_xor_sync(0xffffffffu, w, mask); });
#else
    (void)dst, (void)src, (void)mask;
#endif
  }
  template <class T>
  D2GS_HD T atomic_add(T* address, T value) const {
#if defined(__CUDA_ARCH__)
    return atomicAdd(address, value);
#else
    return (void)address, value;
#endif
  }
};

// kernel<<<grid, block>>>(args) for a kernel body: its shared memory, its block, its arguments.
template <class Body, class Args>
__global__ void kernel_shell(const Args args) {
  __shared__ typename Body::Shared shared;
  DeviceBlock block;
  Body::run(block, shared, args);
}

}  // namespace d2gs::cuda
