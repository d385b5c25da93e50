#pragma once
// Branch-free math for the CPU tile loops: written so that GCC/Clang vectorise loops that call it
// (baseline SSE2 included), which the libm functions prevent without -ffast-math.
#include <bit>
#include <cmath>
#include <cstdint>

// Only the CPU tile loops include this header. Passing the 64/128-byte row vectors between (inlined,
// internal) functions makes GCC note that the ABI would differ with AVX-512 enabled; nothing here has
// external linkage across translation units built with different flags, so the note is silenced.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace d2gs::render::cpu {

// exp(x) for x <= 0 in float, about 1 ulp (Cephes-style range reduction x = n ln2 + r with a degree-6
// polynomial). Inputs below -80 return exp(-80) (~1.8e-35): callers multiply by an opacity >= 1/255 and
// compare with 1/255, so the result is "0" for them, and products stay far from the denormal range
// (denormal operands cost ~100 cycles each and made the tile loops 20x slower).
inline float exp_lanes(float x) {
  x = x < -80.0f ? -80.0f : x;
  x = x > 88.0f ? 88.0f : x;
  constexpr float kRound = 12582912.0f;  // 1.5 * 2^23: adding and subtracting rounds to an integer
  const float n = (x * 1.44269504088896341f + kRound) - kRound;
  float r = x - n * 0.693359375f;
  r = r - n * -2.12194440e-4f;
  const float r2 = r * r;
  float p = 1.9875691500e-4f;
  p = p * r + 1.3981999507e-3f;
  p = p * r + 8.3334519073e-3f;
  p = p * r + 4.1665795894e-2f;
  p = p * r + 1.6666665459e-1f;
  p = p * r + 5.0000001201e-1f;
  const float y = p * r2 + r + 1.0f;
  const std::int32_t bits = (static_cast<std::int32_t>(n) + 127) << 23;
  return y * std::bit_cast<float>(bits);
}
inline double exp_lanes(double x) { return std::exp(x); }

// A SIMD vector of the widest width the target has (16 bytes on the SSE2 baseline, 32 with AVX, 64 with
// AVX-512 under -march=native): a tile row of 16 pixels is kChunks such vectors. GCC/Clang vector
// extensions; wider-than-native vectors would be split into scalar code by GCC, so they are avoided.
#if defined(__AVX512F__)
inline constexpr int kVectorBytes = 64;
#elif defined(__AVX__)
inline constexpr int kVectorBytes = 32;
#else
inline constexpr int kVectorBytes = 16;
#endif
template <typename T>
struct Row;
template <>
struct Row<float> {
  typedef float V __attribute__((vector_size(kVectorBytes)));
  typedef std::int32_t M __attribute__((vector_size(kVectorBytes)));
  static constexpr int kLanes = kVectorBytes / 4;
};
template <>
struct Row<double> {
  typedef double V __attribute__((vector_size(kVectorBytes)));
  typedef std::int64_t M __attribute__((vector_size(kVectorBytes)));
  static constexpr int kLanes = kVectorBytes / 8;
};

// exp of every lane, the lane-wise exp_lanes above (same polynomial for float, std::exp for double).
inline Row<float>::V exp_row(Row<float>::V x) {
  using V = Row<float>::V;
  using M = Row<float>::M;
  x = x < -80.0f ? V{} - 80.0f : x;
  x = x > 88.0f ? V{} + 88.0f : x;
  constexpr float kRound = 12582912.0f;
  const V n = (x * 1.44269504088896341f + kRound) - kRound;
  V r = x - n * 0.693359375f;
  r = r - n * -2.12194440e-4f;
  const V r2 = r * r;
  V p = V{} + 1.9875691500e-4f;
  p = p * r + 1.3981999507e-3f;
  p = p * r + 8.3334519073e-3f;
  p = p * r + 4.1665795894e-2f;
  p = p * r + 1.6666665459e-1f;
  p = p * r + 5.0000001201e-1f;
  const V y = p * r2 + r + 1.0f;
  const M bits = (__builtin_convertvector(n, M) + 127) << 23;
  return y * std::bit_cast<V>(bits);
}
inline Row<double>::V exp_row(Row<double>::V x) {
  for (int k = 0; k < Row<double>::kLanes; ++k) x[k] = std::exp(x[k]);
  return x;
}

}  // namespace d2gs::render::cpu
