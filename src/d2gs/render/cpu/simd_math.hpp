#pragma once
// Branch-free math for the CPU tile loops, on GCC/Clang vector extensions.
//
// Included only by the compositing tile kernels (composite_tiles.ipp), which are compiled once per
// x86-64 level (composite_tiles_*.cpp). Every definition here lives in the namespace named by
// D2GS_TILE_ISA, so the copies built for different instruction sets never meet at link time.
#include <bit>
#include <cmath>
#include <cstdint>

#if defined(__SSE2__)
#include <immintrin.h>
#endif

#include "d2gs/render/composite_math.hpp"

#ifndef D2GS_TILE_ISA
#error "simd_math.hpp belongs to the tile kernels: define D2GS_TILE_ISA (see composite_tiles.ipp)"
#endif

// Passing the 32/64-byte row vectors between (inlined, internal) functions makes GCC note that the ABI
// would differ with another -march; nothing here has linkage across translation units, so the note is
// silenced.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace d2gs::render::cpu::D2GS_TILE_ISA {

// A SIMD vector of the widest width the target has (16 bytes on the SSE2 baseline, 32 with AVX2, 64
// with AVX-512): a tile row of 16 pixels is 16 / kLanes such vectors. Wider-than-native vectors would
// be split into scalar code by GCC, so they are avoided.
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

#define D2GS_TILE_INLINE inline __attribute__((always_inline))

// a * b + c. The tile translation units are compiled with -ffp-contract=off so that the forward and
// the backward kernel evaluate alpha with bit-identical roundings (the backward replays the forward's
// decisions); fused operations are asked for here, explicitly, where the target has them.
D2GS_TILE_INLINE Row<float>::V fmadd(Row<float>::V a, Row<float>::V b, Row<float>::V c) {
#if defined(__AVX512F__)
  return _mm512_fmadd_ps(a, b, c);
#elif defined(__FMA__)
  return _mm256_fmadd_ps(a, b, c);
#else
  return a * b + c;
#endif
}
D2GS_TILE_INLINE Row<double>::V fmadd(Row<double>::V a, Row<double>::V b, Row<double>::V c) {
#if defined(__AVX512F__)
  return _mm512_fmadd_pd(a, b, c);
#elif defined(__FMA__)
  return _mm256_fmadd_pd(a, b, c);
#else
  return a * b + c;
#endif
}

// a > b ? a : b and a < b ? a : b, lane-wise, with the ternaries' exact results (for a NaN or two zeros
// of either sign, b): what MAXPS/MINPS compute, so one instruction where the target has them (GCC does
// not turn the ternaries into them without -ffinite-math-only -fno-signed-zeros).
template <typename V>
D2GS_TILE_INLINE V lane_max(V a, V b) {
#if defined(__AVX512F__)
  if constexpr (sizeof(V) == 64 && sizeof(a[0]) == 4) return _mm512_maskz_max_ps(__mmask16(0xFFFF), a, b);  // not _mm512_max_ps: GCC 12 warns inside it
  if constexpr (sizeof(V) == 64 && sizeof(a[0]) == 8) return _mm512_maskz_max_pd(__mmask8(0xFF), a, b);
#endif
#if defined(__AVX__)
  if constexpr (sizeof(V) == 32 && sizeof(a[0]) == 4) return _mm256_max_ps(a, b);
  if constexpr (sizeof(V) == 32 && sizeof(a[0]) == 8) return _mm256_max_pd(a, b);
#endif
#if defined(__SSE2__)
  if constexpr (sizeof(V) == 16 && sizeof(a[0]) == 4) return _mm_max_ps(a, b);
  if constexpr (sizeof(V) == 16 && sizeof(a[0]) == 8) return _mm_max_pd(a, b);
#endif
  return a > b ? a : b;
}
template <typename V>
D2GS_TILE_INLINE V lane_min(V a, V b) {
#if defined(__AVX512F__)
  if constexpr (sizeof(V) == 64 && sizeof(a[0]) == 4) return _mm512_maskz_min_ps(__mmask16(0xFFFF), a, b);  // not _mm512_min_ps: GCC 12 warns inside it
  if constexpr (sizeof(V) == 64 && sizeof(a[0]) == 8) return _mm512_maskz_min_pd(__mmask8(0xFF), a, b);
#endif
#if defined(__AVX__)
  if constexpr (sizeof(V) == 32 && sizeof(a[0]) == 4) return _mm256_min_ps(a, b);
  if constexpr (sizeof(V) == 32 && sizeof(a[0]) == 8) return _mm256_min_pd(a, b);
#endif
#if defined(__SSE2__)
  if constexpr (sizeof(V) == 16 && sizeof(a[0]) == 4) return _mm_min_ps(a, b);
  if constexpr (sizeof(V) == 16 && sizeof(a[0]) == 8) return _mm_min_pd(a, b);
#endif
  return a < b ? a : b;
}

// m ? a : b and m ? a : 0, lane-wise, for masks whose lanes are all ones or zero (every mask the tile
// loops build): a blend (or an AND) on the mask as it is, where GCC's generic lowering of the vector
// ternary first normalises the mask with two compares against zero. Same lanes as the ternaries.
template <typename M, typename V>
D2GS_TILE_INLINE V select(M m, V a, V b) {
  static_assert(sizeof(M) == sizeof(V));
#if defined(__AVX__) && !defined(__AVX512F__)
  if constexpr (sizeof(V) == 32) return std::bit_cast<V>(_mm256_blendv_ps(std::bit_cast<__m256>(b), std::bit_cast<__m256>(a), std::bit_cast<__m256>(m)));
#endif
#if defined(__SSE2__) && !defined(__AVX__)
  if constexpr (sizeof(V) == 16) {
    const __m128i mi = std::bit_cast<__m128i>(m);
    return std::bit_cast<V>(_mm_or_si128(_mm_and_si128(mi, std::bit_cast<__m128i>(a)), _mm_andnot_si128(mi, std::bit_cast<__m128i>(b))));
  }
#endif
  return m ? a : b;
}
template <typename M, typename V>
D2GS_TILE_INLINE V select_or_zero(M m, V a) {
  static_assert(sizeof(M) == sizeof(V));
  return std::bit_cast<V>(m & std::bit_cast<M>(a));
}

// exp of every lane for x <= 0 in float, about 1 ulp (Cephes-style range reduction x = n ln2 + r with a
// degree-6 polynomial). Inputs below -80 return exp(-80) (~1.8e-35): callers multiply by an opacity
// >= 1/255 and compare with 1/255, so the result is "0" for them, and products stay far from the
// denormal range (denormal operands cost ~100 cycles each and made the tile loops 20x slower).
// The constants of exp_row as whole vectors in memory. The tile loops reach them through a pointer the
// compiler cannot see through (exp_constants()), so that each is an instruction's memory operand: GCC
// otherwise broadcasts every scalar constant into a register anew on each use once registers run out.
struct alignas(64) ExpConstants {
  Row<float>::V lo, hi, log2e, round, ln2_hi, ln2_lo, c0, c1, c2, c3, c4, c5, one;
};
// The values are composite_math.hpp's, whose composite_exp is this function for one lane (the CUDA
// compositing kernels call it).
static constexpr ExpConstants kExpConstants = {
    Row<float>::V{} + kExpLo, Row<float>::V{} + kExpHi, Row<float>::V{} + kExpLog2e,
    Row<float>::V{} + kExpRound, Row<float>::V{} + kExpLn2Hi, Row<float>::V{} + kExpLn2Lo,
    Row<float>::V{} + kExpC0, Row<float>::V{} + kExpC1, Row<float>::V{} + kExpC2,
    Row<float>::V{} + kExpC3, Row<float>::V{} + kExpC4, Row<float>::V{} + kExpC5,
    Row<float>::V{} + 1.0f};
D2GS_TILE_INLINE const ExpConstants* exp_constants() {
  const ExpConstants* p = &kExpConstants;
  asm("" : "+r"(p));
  return p;
}
D2GS_TILE_INLINE Row<float>::V exp_row(Row<float>::V x, const ExpConstants& k = kExpConstants) {
  using V = Row<float>::V;
  using M = Row<float>::M;
  x = lane_max(k.lo, x);  // x < -80 ? -80 : x
  x = lane_min(k.hi, x);  // x > 88 ? 88 : x
  const V n = fmadd(x, k.log2e, k.round) - k.round;  // 1.5 * 2^23: adding and subtracting rounds to an integer
  V r = fmadd(n, k.ln2_hi, x);
  r = fmadd(n, k.ln2_lo, r);
  const V r2 = r * r;
  V p = k.c0;
  p = fmadd(p, r, k.c1);
  p = fmadd(p, r, k.c2);
  p = fmadd(p, r, k.c3);
  p = fmadd(p, r, k.c4);
  p = fmadd(p, r, k.c5);
  const V y = fmadd(p, r2, r) + k.one;
  const M bits = (__builtin_convertvector(n, M) + 127) << 23;
  return y * std::bit_cast<V>(bits);
}
D2GS_TILE_INLINE Row<double>::V exp_row(Row<double>::V x, const ExpConstants& = kExpConstants) {
  for (int k = 0; k < Row<double>::kLanes; ++k) x[k] = std::exp(x[k]);
  return x;
}

// Square root of every lane, correctly rounded (the value std::sqrt gives each lane).
D2GS_TILE_INLINE Row<float>::V sqrt_row(Row<float>::V x) {
#if defined(__AVX512F__)
  return _mm512_maskz_sqrt_ps(__mmask16(0xFFFF), x);  // not _mm512_sqrt_ps: GCC 12 warns inside it
#elif defined(__AVX__)
  return _mm256_sqrt_ps(x);
#elif defined(__SSE2__)
  return _mm_sqrt_ps(x);
#else
  for (int k = 0; k < Row<float>::kLanes; ++k) x[k] = std::sqrt(x[k]);
  return x;
#endif
}
D2GS_TILE_INLINE Row<double>::V sqrt_row(Row<double>::V x) {
#if defined(__AVX512F__)
  return _mm512_maskz_sqrt_pd(__mmask8(0xFF), x);
#elif defined(__AVX__)
  return _mm256_sqrt_pd(x);
#elif defined(__SSE2__)
  return _mm_sqrt_pd(x);
#else
  for (int k = 0; k < Row<double>::kLanes; ++k) x[k] = std::sqrt(x[k]);
  return x;
#endif
}

// Bit k set when lane k of the mask is set (lanes are 0 or -1).
template <typename M>
D2GS_TILE_INLINE std::uint32_t lane_bits(M m) {
  constexpr int L = int(sizeof(M) / sizeof(m[0]));
#if defined(__AVX512F__)
  if constexpr (sizeof(M) == 64 && L == 16) return _mm512_test_epi32_mask((__m512i)m, (__m512i)m);
  if constexpr (sizeof(M) == 64 && L == 8) return _mm512_test_epi64_mask((__m512i)m, (__m512i)m);
#endif
#if defined(__AVX__)
  if constexpr (sizeof(M) == 32 && L == 8) return static_cast<std::uint32_t>(_mm256_movemask_ps((__m256)m));
  if constexpr (sizeof(M) == 32 && L == 4) return static_cast<std::uint32_t>(_mm256_movemask_pd((__m256d)m));
#endif
#if defined(__SSE2__)
  if constexpr (sizeof(M) == 16 && L == 4) return static_cast<std::uint32_t>(_mm_movemask_ps((__m128)m));
  if constexpr (sizeof(M) == 16 && L == 2) return static_cast<std::uint32_t>(_mm_movemask_pd((__m128d)m));
#endif
  std::uint32_t bits = 0;
  for (int k = 0; k < L; ++k) bits |= std::uint32_t(m[k] & 1) << k;
  return bits;
}

// True when any lane of the mask is set.
template <typename M>
D2GS_TILE_INLINE bool any_lane(M m) {
#if defined(__AVX512F__)
  if constexpr (sizeof(M) == 64 && sizeof(m[0]) == 4) return _mm512_test_epi32_mask((__m512i)m, (__m512i)m) != 0;
  if constexpr (sizeof(M) == 64 && sizeof(m[0]) == 8) return _mm512_test_epi64_mask((__m512i)m, (__m512i)m) != 0;
#endif
#if defined(__AVX__)
  if constexpr (sizeof(M) == 32) return !_mm256_testz_si256((__m256i)m, (__m256i)m);
#endif
#if defined(__SSE2__)
  if constexpr (sizeof(M) == 16) return _mm_movemask_epi8((__m128i)m) != 0;
#endif
  std::int64_t acc = 0;
  for (int k = 0; k < int(sizeof(M) / sizeof(m[0])); ++k) acc |= m[k];
  return acc != 0;
}

// Number of set lanes (lanes are 0 or -1).
template <typename M>
D2GS_TILE_INLINE int count_lanes(M m) {
  return std::popcount(lane_bits(m));
}

// Sum of the lanes in a fixed pairwise order (halves added until one lane is left): the same order on
// every call, so gradients are reproducible.
template <typename V>
D2GS_TILE_INLINE auto sum_lanes(V v) {
  constexpr int L = int(sizeof(V) / sizeof(v[0]));
  if constexpr (L == 16) {
    typedef decltype(v[0] + 0) S;
    typedef S H __attribute__((vector_size(sizeof(V) / 2)));
    const H lo = __builtin_shufflevector(v, v, 0, 1, 2, 3, 4, 5, 6, 7);
    const H hi = __builtin_shufflevector(v, v, 8, 9, 10, 11, 12, 13, 14, 15);
    return sum_lanes(lo + hi);
  } else if constexpr (L == 8) {
    typedef decltype(v[0] + 0) S;
    typedef S H __attribute__((vector_size(sizeof(V) / 2)));
    const H lo = __builtin_shufflevector(v, v, 0, 1, 2, 3);
    const H hi = __builtin_shufflevector(v, v, 4, 5, 6, 7);
    return sum_lanes(lo + hi);
  } else if constexpr (L == 4) {
    return (v[0] + v[2]) + (v[1] + v[3]);
  } else if constexpr (L == 2) {
    return v[0] + v[1];
  } else {
    return v[0];
  }
}

// sum_lanes of four vectors at once, bit for bit the same four results: for eight float lanes the
// halves of two vectors are added in one vector addition, then the pairs (h0 + h2, h1 + h3) of four, then
// their sums, instead of three shuffle-and-add rounds per vector.
template <typename V>
D2GS_TILE_INLINE void sum_lanes4(V a, V b, V c, V d, decltype(a[0] + 0) out[4]) {
  if constexpr (sizeof(V) / sizeof(a[0]) == 8 && sizeof(a[0]) == 4) {
    const V sab = __builtin_shufflevector(a, b, 0, 1, 2, 3, 8, 9, 10, 11) +
                  __builtin_shufflevector(a, b, 4, 5, 6, 7, 12, 13, 14, 15);  // a lo + hi | b lo + hi
    const V scd = __builtin_shufflevector(c, d, 0, 1, 2, 3, 8, 9, 10, 11) +
                  __builtin_shufflevector(c, d, 4, 5, 6, 7, 12, 13, 14, 15);
    // h0 + h2, h1 + h3 of a, c | of b, d
    const V u = __builtin_shufflevector(sab, scd, 0, 1, 8, 9, 4, 5, 12, 13) +
                __builtin_shufflevector(sab, scd, 2, 3, 10, 11, 6, 7, 14, 15);
    const V w = __builtin_shufflevector(u, u, 0, 2, 4, 6, 0, 2, 4, 6) +
                __builtin_shufflevector(u, u, 1, 3, 5, 7, 1, 3, 5, 7);  // a, c, b, d
    out[0] = w[0];
    out[1] = w[2];
    out[2] = w[1];
    out[3] = w[3];
  } else {
    out[0] = sum_lanes(a);
    out[1] = sum_lanes(b);
    out[2] = sum_lanes(c);
    out[3] = sum_lanes(d);
  }
}

}  // namespace d2gs::render::cpu::D2GS_TILE_ISA
