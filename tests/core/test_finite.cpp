// all_finite: the trainer's guard against NaN and infinite gradients and parameters.
#include <gtest/gtest.h>

#include <omp.h>

#include <bit>
#include <cmath>
#include <cstddef>
#include <limits>
#include <vector>

#include "d2gs/core/finite.hpp"

namespace d2gs {
namespace {

// Every size around the vector widths, the parallel threshold (65 536) and the split between two threads.
const std::size_t kSizes[] = {0, 1, 7, 8, 15, 16, 17, 33, 65535, 65536, 65537, 200003};

TEST(Finite, FiniteExtremesAreFinite) {
  const float extremes[] = {0.0f, -0.0f, std::numeric_limits<float>::max(), std::numeric_limits<float>::lowest(),
                            std::numeric_limits<float>::min(), std::numeric_limits<float>::denorm_min(),
                            -std::numeric_limits<float>::denorm_min(), 1e-30f, -3.5f};
  for (const std::size_t n : kSizes) {
    std::vector<float> v(n);
    for (std::size_t i = 0; i < n; ++i) v[i] = extremes[i % std::size(extremes)];
    EXPECT_TRUE(all_finite(v)) << n;
  }
}

// One bad value anywhere (first, last, either thread's share, inside and outside a vector's width) is found,
// at one thread and at two.
TEST(Finite, OneNanOrInfinityAnywhereIsFound) {
  const float bad[] = {std::numeric_limits<float>::quiet_NaN(), -std::numeric_limits<float>::quiet_NaN(),
                       std::numeric_limits<float>::signaling_NaN(), std::numeric_limits<float>::infinity(),
                       -std::numeric_limits<float>::infinity(), std::bit_cast<float>(0x7f800001u),
                       std::bit_cast<float>(0xffffffffu)};
  const int saved = omp_get_max_threads();
  for (const int threads : {1, 2}) {
    omp_set_num_threads(threads);
    for (const std::size_t n : kSizes) {
      if (n == 0) continue;
      std::vector<float> v(n, 1.0f);
      for (const std::size_t at : {std::size_t{0}, n / 2 - (n > 1 ? 1 : 0), n / 2, n - 1}) {
        for (const float b : bad) {
          v[at] = b;
          EXPECT_FALSE(all_finite(v)) << "n " << n << " at " << at << " threads " << threads;
          v[at] = 1.0f;
        }
      }
      EXPECT_TRUE(all_finite(v)) << n;
    }
  }
  omp_set_num_threads(saved);
}

}  // namespace
}  // namespace d2gs
