#include <gtest/gtest.h>

#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/core/percentile.hpp"

namespace d2gs {
namespace {

TEST(Percentile, MatchesNumpyLinearInterpolation) {
  // np.percentile([1, 2, 3, 4], 10) = 1.3 ; np.percentile([5, 1, 3], 50) = 3 ; 95 of 0..100 = 95.
  EXPECT_NEAR(percentile({1, 2, 3, 4}, 10), 1.3, 1e-6);
  EXPECT_NEAR(percentile({5, 1, 3}, 50), 3.0, 1e-12);
  std::vector<float> v(101);
  for (int i = 0; i <= 100; ++i) v[i] = static_cast<float>(i);
  EXPECT_NEAR(percentile(v, 95), 95.0, 1e-9);
  // numpy.percentile(range(1, 1001), [0.1, 99.9]) = 1.999, 999.001
  std::vector<double> w(1000);
  for (int i = 0; i < 1000; ++i) w[i] = i + 1;
  EXPECT_NEAR(percentile(w, 0.1), 1.999, 1e-9);
  EXPECT_NEAR(percentile(w, 99.9), 999.001, 1e-9);
}

TEST(Percentile, ClampsQAndRefusesAnEmptySet) {
  EXPECT_EQ(percentile({3, 1, 2}, -5), 1.0);
  EXPECT_EQ(percentile({3, 1, 2}, 250), 3.0);
  EXPECT_THROW(percentile(std::vector<float>{}, 50), Error);
}

}  // namespace
}  // namespace d2gs
