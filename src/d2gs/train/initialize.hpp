#pragma once
// Initial Gaussians from a point cloud (method.md §2 "init"): one Gaussian per point, SH DC from the
// colour ((rgb − 0.5) / C0), higher SH zero, isotropic log-scale log(sqrt(mean squared distance to the 3
// nearest other points)) with the squared distance floored at 1e-7, identity rotation, opacity 0.1.
#include <cstdint>
#include <vector>

#include "d2gs/model/gaussians.hpp"
#include "d2gs/model/point_cloud.hpp"
#include "d2gs/scene/scene.hpp"

namespace d2gs {

Gaussians gaussians_from_point_cloud(const PointCloud& cloud, int sh_degree = kMaxShDegree,
                                     float initial_opacity = 0.1f);

// The depth range of `--init random`. With dataset points: per training view, the 0.1 and 99.9
// percentiles of the depths of the points in front of it that project into its image (how LLFF's
// imgs2poses computes poses_bounds.npy's near/far), then the smallest near and the largest far over the
// views. This is the only thing the random init takes from the all-view points: the same bounds every
// LLFF method samples its rays in. Without dataset points (or fewer than 20 in view): 0.5·E … 50·E, E =
// the scene extent.
struct RandomInitRange {
  double near = 0, far = 0;
  bool from_dataset_points = false;
};
RandomInitRange random_init_depth_range(const Scene& scene, const std::vector<int>& train_views, float extent);

// Random initial cloud: `count` points, each on the ray of a random pixel of a random training view at
// a depth with uniform inverse depth in [1/far, 1/near] (as NeRF samples LLFF rays in disparity); random
// colours. Throws if the range is not 0 < near < far.
PointCloud random_point_cloud(const Scene& scene, const std::vector<int>& train_views, int count,
                              const RandomInitRange& range, std::uint64_t seed);

}  // namespace d2gs
