#pragma once
// k-nearest-neighbour statistics over a point set (nanoflann k-d tree), used for the initial Gaussian
// scales (mean squared distance to the 3 nearest other points, as 3DGS's distCUDA2) and for DD-Drop's
// density (mean distance to the 6 nearest other Gaussians). Each point's query is independent, so
// the result is the same whatever the thread count.
#include <cstddef>
#include <vector>

namespace d2gs {

enum class KnnStatistic { MeanSquaredDistance, MeanDistance };

// For each of the n points (xyz interleaved), the mean over its k nearest *other* points of the
// squared or plain Euclidean distance. With fewer than k other points, the mean is over those there are
// (0 when a point is alone).
std::vector<float> knn_mean_distance(const float* xyz, std::size_t n, int k, KnnStatistic statistic);

// For each of the n query points, the Euclidean distance to its nearest point of the m reference points
// (xyz interleaved; infinity when m = 0).
std::vector<float> nearest_distances(const float* query, std::size_t n, const float* reference, std::size_t m);

}  // namespace d2gs
