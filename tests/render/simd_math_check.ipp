// Checks of the helpers of src/d2gs/render/cpu/simd_math.hpp against what they stand for (the vector
// ternaries and sum_lanes, bit for bit, NaN and signed zeros included). Not a header: compiled once per
// x86-64 level by simd_math_check_<level>.cpp, which defines D2GS_TILE_ISA; test_simd_math.cpp runs the
// levels this CPU supports.
#include <bit>
#include <cstdint>
#include <limits>
#include <string>

#include "d2gs/render/cpu/simd_math.hpp"

namespace d2gs::render::cpu::D2GS_TILE_ISA {

namespace {

template <typename T>
std::string bits_of(T x) {
  if constexpr (sizeof(T) == 4) return std::to_string(std::bit_cast<std::uint32_t>(x));
  else return std::to_string(std::bit_cast<std::uint64_t>(x));
}

template <typename T>
bool same_bits(T a, T b) {
  if constexpr (sizeof(T) == 4) return std::bit_cast<std::uint32_t>(a) == std::bit_cast<std::uint32_t>(b);
  else return std::bit_cast<std::uint64_t>(a) == std::bit_cast<std::uint64_t>(b);
}

// Values where min/max and selects can differ from the ternaries: zeros of both signs, NaN, infinities,
// the clamp bounds of exp_row and alpha, a denormal.
template <typename T>
constexpr T kSpecials[] = {T(0),     -T(0),    T(1),    T(-1),   T(0.99), T(0.5),
                           T(-80),   T(-80.5), T(88),   T(100),  std::numeric_limits<T>::infinity(),
                           -std::numeric_limits<T>::infinity(),  std::numeric_limits<T>::quiet_NaN(),
                           std::numeric_limits<T>::denorm_min(), T(1e-30), T(-1e-30)};
constexpr int kNumSpecials = 16;

// Lane k of row vector `shift` of the specials.
template <typename V, typename T>
V specials_row(int shift) {
  V v = {};
  for (int k = 0; k < int(sizeof(V) / sizeof(T)); ++k) v[k] = kSpecials<T>[(shift + k * 5) % kNumSpecials];
  return v;
}

template <typename T>
std::string check_min_max_select() {
  using V = typename Row<T>::V;
  using M = typename Row<T>::M;
  constexpr int L = Row<T>::kLanes;
  for (int i = 0; i < kNumSpecials; ++i)
    for (int j = 0; j < kNumSpecials; ++j) {
      const V a = specials_row<V, T>(i), b = specials_row<V, T>(j);
      const V mx = lane_max(a, b), mn = lane_min(a, b);
      const M lt = a < b, gt = a > b;
      const V sel = select(lt, a, b), zero_or = select_or_zero(gt, a);
      for (int k = 0; k < L; ++k) {
        const T ak = a[k], bk = b[k];
        const std::string at = " at lanes " + bits_of(ak) + ", " + bits_of(bk);
        if (!same_bits(mx[k], ak > bk ? ak : bk)) return "lane_max" + at;
        if (!same_bits(mn[k], ak < bk ? ak : bk)) return "lane_min" + at;
        if (!same_bits(sel[k], ak < bk ? ak : bk)) return "select" + at;
        if (!same_bits(zero_or[k], ak > bk ? ak : T(0))) return "select_or_zero" + at;
      }
    }
  for (int k = -1; k < L; ++k) {  // no lane, then each single lane
    M m = {};
    if (k >= 0) m[k] = -1;
    if (any_lane(m) != (k >= 0)) return "any_lane with lane " + std::to_string(k);
    if (count_lanes(m) != (k >= 0 ? 1 : 0)) return "count_lanes with lane " + std::to_string(k);
    if (count_lanes(M{} - 1) != L) return "count_lanes of a full mask";
  }
  return "";
}

std::string check_sum_lanes4() {
  using V = Row<float>::V;
  constexpr int L = Row<float>::kLanes;
  std::uint32_t state = 12345;
  const auto next = [&state] {  // values of many magnitudes and both signs, so the order shows
    state = state * 1664525u + 1013904223u;
    const float mant = float(state >> 8) / float(1 << 24) - 0.5f;
    return mant * float(1 << ((state >> 3) % 24));
  };
  for (int trial = 0; trial < 1000; ++trial) {
    V v[4];
    for (auto& x : v)
      for (int k = 0; k < L; ++k) x[k] = next();
    float out[4];
    sum_lanes4(v[0], v[1], v[2], v[3], out);
    for (int i = 0; i < 4; ++i)
      if (!same_bits(out[i], float(sum_lanes(v[i])))) return "sum_lanes4 result " + std::to_string(i);
  }
  return "";
}

}  // namespace

// exp_row of n values (n a multiple of the lanes), for the comparison with composite_math.hpp's
// composite_exp in test_simd_math.cpp (compiled at the baseline level: composite_exp is an inline function
// of no ISA namespace, so it is only instantiated there).
void exp_row_values(const float* in, float* out, int n) {
  using V = Row<float>::V;
  constexpr int L = Row<float>::kLanes;
  for (int i = 0; i + L <= n; i += L) {
    V v;
    for (int k = 0; k < L; ++k) v[k] = in[i + k];
    const V e = exp_row(v);
    for (int k = 0; k < L; ++k) out[i + k] = e[k];
  }
}
bool exp_row_fuses() {
#if defined(__FMA__) || defined(__AVX512F__)
  return true;
#else
  return false;
#endif
}

// The first mismatch found, or "" when every check passes.
std::string simd_math_mismatch() {
  for (const std::string& r : {check_min_max_select<float>(), check_min_max_select<double>(), check_sum_lanes4()})
    if (!r.empty()) return r;
  return "";
}

}  // namespace d2gs::render::cpu::D2GS_TILE_ISA
