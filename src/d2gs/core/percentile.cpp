#include "d2gs/core/percentile.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>

#include "d2gs/core/error.hpp"
#include "d2gs/core/float_order.hpp"

namespace d2gs {

template <typename T>
double percentile(std::vector<T> values, double q) {
  if (values.empty()) fail("percentile of an empty set");
  std::sort(values.begin(), values.end());
  const double pos = std::clamp(q, 0.0, 100.0) / 100.0 * static_cast<double>(values.size() - 1);
  const auto lo = static_cast<std::size_t>(std::floor(pos));
  const auto hi = std::min(lo + 1, values.size() - 1);
  const double frac = pos - static_cast<double>(lo);
  return static_cast<double>(values[lo]) + frac * (static_cast<double>(values[hi]) - static_cast<double>(values[lo]));
}

template double percentile<float>(std::vector<float> values, double q);
template double percentile<double>(std::vector<double> values, double q);

namespace {

// Of `count` keys (from get(i)) with the bits above `shift + bits` equal, the bucket of bits
// [shift, shift + bits) that holds rank k; k becomes the rank within that bucket.
template <class Get>
std::uint32_t bucket_of_rank(std::size_t count, Get&& get, int shift, int bits, std::size_t& k) {
  std::array<std::size_t, 2048> hist{};
  const std::uint32_t mask = (1u << bits) - 1u;
  for (std::size_t i = 0; i < count; ++i) ++hist[(get(i) >> shift) & mask];
  for (std::uint32_t b = 0;; ++b) {
    if (k < hist[b]) return b;
    k -= hist[b];
  }
}

}  // namespace

float kth_smallest(const float* values, std::size_t n, std::size_t k) {
  if (k >= n) fail("k-th smallest: rank {} of {} values", k, n);
  // Bits 31..21, then 20..10 of the keys whose top bits match, then 9..0 of those.
  const std::uint32_t top = bucket_of_rank(n, [&](std::size_t i) { return float_order_key(values[i]); }, 21, 11, k);
  std::vector<std::uint32_t> keys;
  for (std::size_t i = 0; i < n; ++i)
    if (const std::uint32_t key = float_order_key(values[i]); (key >> 21) == top) keys.push_back(key);
  const std::uint32_t mid = bucket_of_rank(keys.size(), [&](std::size_t i) { return keys[i]; }, 10, 11, k);
  std::size_t kept = 0;
  for (const std::uint32_t key : keys)
    if (((key >> 10) & 0x7ffu) == mid) keys[kept++] = key;
  const std::uint32_t low = bucket_of_rank(kept, [&](std::size_t i) { return keys[i]; }, 0, 10, k);
  const float v = float_from_order_key((top << 21) | (mid << 10) | low);
  if (std::isnan(v)) fail("k-th smallest: a NaN among the values");
  return v;
}

}  // namespace d2gs
