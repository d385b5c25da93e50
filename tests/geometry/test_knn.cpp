#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "d2gs/geometry/knn.hpp"

namespace d2gs {
namespace {

// Brute force: sort the distances to all other points, average the k smallest.
std::vector<double> brute_force(const std::vector<float>& xyz, int k, bool squared) {
  const std::size_t n = xyz.size() / 3;
  std::vector<double> out(n);
  for (std::size_t i = 0; i < n; ++i) {
    std::vector<double> d;
    for (std::size_t j = 0; j < n; ++j) {
      if (j == i) continue;
      double s = 0;
      for (int c = 0; c < 3; ++c) {
        const double diff = static_cast<double>(xyz[i * 3 + c]) - xyz[j * 3 + c];
        s += diff * diff;
      }
      d.push_back(squared ? s : std::sqrt(s));
    }
    std::sort(d.begin(), d.end());
    const std::size_t m = std::min<std::size_t>(static_cast<std::size_t>(k), d.size());
    double sum = 0;
    for (std::size_t j = 0; j < m; ++j) sum += d[j];
    out[i] = m ? sum / static_cast<double>(m) : 0.0;
  }
  return out;
}

TEST(Knn, MatchesBruteForceWithDuplicates) {
  std::mt19937 rng(11);
  std::normal_distribution<float> g(0.0f, 1.0f);
  std::vector<float> xyz;
  for (int i = 0; i < 400; ++i)
    for (int c = 0; c < 3; ++c) xyz.push_back(g(rng) * (c == 2 ? 5.0f : 1.0f));
  for (int i = 0; i < 10; ++i)  // exact duplicates of earlier points
    for (int c = 0; c < 3; ++c) xyz.push_back(xyz[static_cast<std::size_t>(i) * 3 + c]);
  const std::size_t n = xyz.size() / 3;
  for (const auto& [k, stat] : {std::pair{3, KnnStatistic::MeanSquaredDistance}, std::pair{6, KnnStatistic::MeanDistance}}) {
    const auto got = knn_mean_distance(xyz.data(), n, k, stat);
    const auto want = brute_force(xyz, k, stat == KnnStatistic::MeanSquaredDistance);
    for (std::size_t i = 0; i < n; ++i) EXPECT_NEAR(got[i], want[i], 1e-5 * (1.0 + want[i])) << "point " << i;
  }
}

TEST(Knn, FewPointsAndBadInput) {
  const std::vector<float> one = {0, 0, 0};
  EXPECT_EQ(knn_mean_distance(one.data(), 1, 3, KnnStatistic::MeanDistance)[0], 0.0f);
  const std::vector<float> two = {0, 0, 0, 3, 4, 0};
  const auto d = knn_mean_distance(two.data(), 2, 3, KnnStatistic::MeanDistance);
  EXPECT_FLOAT_EQ(d[0], 5.0f);
  EXPECT_FLOAT_EQ(d[1], 5.0f);
  const std::vector<float> bad = {0, 0, NAN, 1, 1, 1};
  EXPECT_ANY_THROW(knn_mean_distance(bad.data(), 2, 3, KnnStatistic::MeanDistance));
}

}  // namespace
}  // namespace d2gs
