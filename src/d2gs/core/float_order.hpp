#pragma once
// A float's bits as an unsigned key that orders as the floats do (negatives reversed, below the
// positives), and back: for radix sorts and bucket selections of floats (core/percentile.cpp, the
// DD-Drop kernels' CUB sort of depths). D2GS_HD: the same functions on the host and in CUDA kernels.
#include <cstdint>
#include <cstring>

#include "d2gs/core/host_device.hpp"

namespace d2gs {

D2GS_HD std::uint32_t float_order_key(float v) {
  std::uint32_t u;
#if defined(__CUDA_ARCH__)
  u = __float_as_uint(v);
#else
  std::memcpy(&u, &v, sizeof u);
#endif
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}

D2GS_HD float float_from_order_key(std::uint32_t key) {
  const std::uint32_t u = (key & 0x80000000u) ? (key & 0x7fffffffu) : ~key;
#if defined(__CUDA_ARCH__)
  return __uint_as_float(u);
#else
  float v;
  std::memcpy(&v, &u, sizeof v);
  return v;
#endif
}

}  // namespace d2gs
