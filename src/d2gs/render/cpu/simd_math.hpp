#pragma once
// Branch-free math for the CPU tile loops: written so that GCC/Clang vectorise loops that call it
// (baseline SSE2 included), which the libm functions prevent without -ffast-math.
#include <bit>
#include <cmath>
#include <cstdint>

namespace d2gs::render::cpu {

// exp(x) for x <= 0 in float, about 1 ulp (Cephes-style range reduction x = n ln2 + r with a degree-6
// polynomial); inputs below -87 return exp(-87) (~1.6e-38), which every caller treats as 0.
inline float exp_lanes(float x) {
  x = x < -87.0f ? -87.0f : x;
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

}  // namespace d2gs::render::cpu
