// The SIMD helpers of the compositing tile loops (render/cpu/simd_math.hpp) give exactly what the
// ternaries and lane sums they replace give, at each level compiled here that this CPU runs.
#include <string>

#include <gtest/gtest.h>

namespace d2gs::render::cpu {
namespace test_baseline {
std::string simd_math_mismatch();
}
#if defined(D2GS_TEST_SIMD_AVX2)
namespace test_avx2 {
std::string simd_math_mismatch();
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

}  // namespace
}  // namespace d2gs::test
