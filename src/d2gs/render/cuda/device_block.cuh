#pragma once
// The GPU side of the kernel shape (render/kernels/block.hpp): DeviceBlock answers a kernel body's
// requests with the CUDA built-ins, and kernel_shell is the one __global__ function every kernel body is
// launched through. The CPU emulator (render/kernels/emulate.hpp) answers the same requests on the host.
#include <cuda_runtime.h>

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
  template <class T>
  D2GS_HD void shfl_up(Reg<T>& dst, const Reg<T>& src, int delta) const {
#if defined(__CUDA_ARCH__)
    dst.value = __shfl_up_sync(0xffffffffu, src.value, static_cast<unsigned>(delta));
#else
    (void)dst, (void)src, (void)delta;
#endif
  }
  template <class T>
  D2GS_HD void shfl_down(Reg<T>& dst, const Reg<T>& src, int delta) const {
#if defined(__CUDA_ARCH__)
    dst.value = __shfl_down_sync(0xffffffffu, src.value, static_cast<unsigned>(delta));
#else
    (void)dst, (void)src, (void)delta;
#endif
  }
  template <class T>
  D2GS_HD void shfl_xor(Reg<T>& dst, const Reg<T>& src, int mask) const {
#if defined(__CUDA_ARCH__)
    dst.value = __shfl_xor_sync(0xffffffffu, src.value, mask);
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
