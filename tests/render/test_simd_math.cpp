// The SIMD helpers of the compositing tile loops (render/cpu/simd_math.hpp) give exactly what the
// ternaries and lane sums they replace give, at each level compiled here that this CPU runs.
#include <cstring>
#include <limits>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "d2gs/render/composite_math.hpp"

namespace d2gs::render::cpu {
namespace test_baseline {
std::string simd_math_mismatch();
void exp_row_values(const float* in, float* out, int n);
bool exp_row_fuses();
}
#if defined(D2GS_TEST_SIMD_AVX2)
namespace test_avx2 {
std::string simd_math_mismatch();
void exp_row_values(const float* in, float* out, int n);
bool exp_row_fuses();
}
#endif
}  // namespace d2gs::render::cpu

namespace d2gs::test {
namespace {

TEST(SimdMath, HelpersAreTheTernariesBitForBitAtTheBaselineLevel) {
  EXPECT_EQ("", render::cpu::test_baseline::simd_math_mismatch());
}

TEST(SimdMath, HelpersAreTheTernariesBitForBitAtTheAvx2Level) {
#if defined(D2GS_TEST_SIMD_AVX2)
  __builtin_cpu_init();
  if (!__builtin_cpu_supports("x86-64-v3")) GTEST_SKIP() << "this CPU does not run x86-64-v3";
  EXPECT_EQ("", render::cpu::test_avx2::simd_math_mismatch());
#else
  GTEST_SKIP() << "the AVX2 level is not compiled in this build";
#endif
}

// exp_row against composite_exp (composite_math.hpp, which the CUDA compositing kernels call), bit for
// bit with the level's fusing: every float in [-100, 0] on a fine grid, the clamp bounds, and the specials.
std::string exp_mismatch(void (*exp_row_values)(const float*, float*, int), bool fused) {
  std::vector<float> in;
  for (int i = 0; i <= 2000000; ++i) in.push_back(-100.0f * float(i) / 2000000.0f);
  for (float v : {-80.0f, -80.00001f, -79.99999f, 88.0f, 100.0f, -0.0f, 1e-30f, -1e-30f, -1e-45f, -4.5f, -4.0f,
                  std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()})
    in.push_back(v);
  while (in.size() % 16) in.push_back(-1.0f);
  std::vector<float> out(in.size());
  exp_row_values(in.data(), out.data(), static_cast<int>(in.size()));
  for (std::size_t i = 0; i < in.size(); ++i) {
    const float want = fused ? render::composite_exp<true>(in[i]) : render::composite_exp<false>(in[i]);
    if (std::memcmp(&want, &out[i], sizeof want) != 0)
      return "exp(" + std::to_string(in[i]) + "): exp_row " + std::to_string(out[i]) + ", composite_exp " +
             std::to_string(want);
  }
  return "";
}

TEST(SimdMath, ExpRowIsCompositeExpBitForBit) {
  // The "baseline" level fuses only in a -march=native build (D2GS_NATIVE).
  EXPECT_EQ("", exp_mismatch(&render::cpu::test_baseline::exp_row_values, render::cpu::test_baseline::exp_row_fuses()));
#if defined(D2GS_TEST_SIMD_AVX2)
  __builtin_cpu_init();
  if (!__builtin_cpu_supports("x86-64-v3")) GTEST_SKIP() << "this CPU does not run x86-64-v3";
  EXPECT_TRUE(render::cpu::test_avx2::exp_row_fuses());
  EXPECT_EQ("", exp_mismatch(&render::cpu::test_avx2::exp_row_values, true));
#endif
}

}  // namespace
}  // namespace d2gs::test
