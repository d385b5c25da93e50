#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "d2gs/core/error.hpp"
#include "d2gs/core/float_order.hpp"
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

namespace d2gs {
namespace {

// kth_smallest against std::nth_element: random values with many repeats, both signs, both zeros,
// infinities, denormals and a narrow range (one top-level bucket), every rank of small sets.
TEST(KthSmallest, EqualsNthElement) {
  std::mt19937 gen(7);
  const auto check = [](const std::vector<float>& v) {
    for (std::size_t k = 0; k < v.size(); k += std::max<std::size_t>(1, v.size() / 97)) {
      std::vector<float> w = v;
      std::nth_element(w.begin(), w.begin() + static_cast<std::ptrdiff_t>(k), w.end());
      const float got = kth_smallest(v.data(), v.size(), k);
      ASSERT_TRUE(got == w[k]) << "k " << k << " of " << v.size() << ": " << got << " vs " << w[k];
    }
  };
  std::uniform_real_distribution<float> wide(-1e6f, 1e6f), narrow(3.0f, 3.001f);
  std::uniform_int_distribution<int> repeat(0, 20);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<float> v;
    const int n = 1 + trial * 397;
    for (int i = 0; i < n; ++i) v.push_back(trial % 3 == 0 ? narrow(gen) : trial % 3 == 1 ? wide(gen) : float(repeat(gen)));
    if (trial % 4 == 0) {
      v.push_back(0.0f);
      v.push_back(-0.0f);
      v.push_back(std::numeric_limits<float>::infinity());
      v.push_back(-std::numeric_limits<float>::infinity());
      v.push_back(std::numeric_limits<float>::denorm_min());
      v.push_back(-std::numeric_limits<float>::denorm_min());
    }
    check(v);
  }
  const std::vector<float> one = {2.5f};
  EXPECT_EQ(kth_smallest(one.data(), 1, 0), 2.5f);
}

TEST(KthSmallest, RejectsARankOutsideTheValuesAndANaNResult) {
  const std::vector<float> v = {1.0f, 2.0f};
  EXPECT_THROW(kth_smallest(v.data(), v.size(), 2), Error);
  EXPECT_THROW(kth_smallest(v.data(), 0, 0), Error);
  const std::vector<float> nan = {std::numeric_limits<float>::quiet_NaN()};
  EXPECT_THROW(kth_smallest(nan.data(), 1, 0), Error);
}

// The key of a float orders as the floats do (negatives below positives, -0 just below +0, the
// infinities at the ends) and gives the float back bit for bit.
TEST(FloatOrderKey, OrdersAsTheFloatsAndRoundTrips) {
  const float inf = std::numeric_limits<float>::infinity();
  std::vector<float> v = {-inf, -3.3e38f, -2.0f, -1.0f, -1e-30f, -1e-45f, -0.0f, 0.0f, 1e-45f, 1e-30f, 0.5f, 1.0f,
                          3.3e38f, inf};
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-1e6f, 1e6f);
  for (int i = 0; i < 1000; ++i) v.push_back(u(rng));
  for (std::size_t i = 0; i < v.size(); ++i) {
    const float back = float_from_order_key(float_order_key(v[i]));
    EXPECT_EQ(std::signbit(back), std::signbit(v[i]));
    EXPECT_EQ(back, v[i]);
    for (std::size_t j = 0; j < v.size(); ++j) {
      if (!(v[i] < v[j])) continue;
      EXPECT_LT(float_order_key(v[i]), float_order_key(v[j])) << v[i] << " " << v[j];
    }
  }
  EXPECT_LT(float_order_key(-0.0f), float_order_key(0.0f));
}

}  // namespace
}  // namespace d2gs
