#include "d2gs/geometry/knn.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <nanoflann.hpp>

#include "d2gs/core/error.hpp"

namespace d2gs {
namespace {

struct PointAdaptor {
  const float* xyz;
  std::size_t n;
  std::size_t kdtree_get_point_count() const { return n; }
  float kdtree_get_pt(std::size_t i, std::size_t dim) const { return xyz[i * 3 + dim]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};

using Tree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, PointAdaptor>, PointAdaptor, 3,
                                                 std::size_t>;

}  // namespace

std::vector<float> knn_mean_distance(const float* xyz, std::size_t n, int k, KnnStatistic statistic) {
  if (k <= 0) fail("kNN: k must be positive, got {}", k);
  std::vector<float> out(n, 0.0f);
  if (n < 2) return out;
  for (std::size_t i = 0; i < n * 3; ++i)
    if (!std::isfinite(xyz[i])) fail("kNN: point {} has a non-finite coordinate", i / 3);
  const PointAdaptor adaptor{xyz, n};
  Tree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
  const std::size_t want = std::min<std::size_t>(static_cast<std::size_t>(k) + 1, n);
#pragma omp parallel
  {
    std::vector<std::size_t> idx(want);
    std::vector<float> d2(want);
#pragma omp for schedule(static)
    for (std::ptrdiff_t ii = 0; ii < static_cast<std::ptrdiff_t>(n); ++ii) {
      const auto i = static_cast<std::size_t>(ii);
      const std::size_t found = tree.knnSearch(xyz + i * 3, want, idx.data(), d2.data());
      // Drop the point itself (it may not come first when duplicates exist); else drop the farthest.
      std::size_t self = found;
      for (std::size_t j = 0; j < found; ++j)
        if (idx[j] == i) self = j;
      if (self == found) self = found - 1;
      double sum = 0.0;
      std::size_t used = 0;
      for (std::size_t j = 0; j < found; ++j) {
        if (j == self) continue;
        sum += statistic == KnnStatistic::MeanSquaredDistance ? static_cast<double>(d2[j])
                                                              : std::sqrt(static_cast<double>(d2[j]));
        ++used;
      }
      out[i] = used ? static_cast<float>(sum / static_cast<double>(used)) : 0.0f;
    }
  }
  return out;
}

std::vector<float> nearest_distances(const float* query, std::size_t n, const float* reference, std::size_t m) {
  std::vector<float> out(n, std::numeric_limits<float>::infinity());
  if (m == 0 || n == 0) return out;
  const PointAdaptor adaptor{reference, m};
  Tree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  tree.buildIndex();
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t ii = 0; ii < static_cast<std::ptrdiff_t>(n); ++ii) {
    const auto i = static_cast<std::size_t>(ii);
    std::size_t idx = 0;
    float d2 = 0.0f;
    if (tree.knnSearch(query + i * 3, 1, &idx, &d2) == 1) out[i] = std::sqrt(d2);
  }
  return out;
}

}  // namespace d2gs
