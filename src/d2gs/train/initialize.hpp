#pragma once
// Initial Gaussians from a point cloud (method.md §2 "init"): one Gaussian per point, SH DC from the
// colour ((rgb − 0.5) / C0), higher SH zero, isotropic log-scale log(sqrt(mean squared distance to the 3
// nearest other points)) with the squared distance floored at 1e-7, identity rotation, opacity 0.1.
#include "d2gs/model/gaussians.hpp"
#include "d2gs/scene/point_cloud.hpp"

namespace d2gs {

Gaussians gaussians_from_point_cloud(const PointCloud& cloud, int sh_degree = kMaxShDegree,
                                     float initial_opacity = 0.1f);

}  // namespace d2gs
