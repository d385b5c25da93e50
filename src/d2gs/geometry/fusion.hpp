#pragma once
// Depth-map fusion (the role of patch-match stereo's fusion step): per view, the depth candidates of
// its stereo pairs are merged; a depth is kept only when it agrees with the depth map of at least one
// other view at the pixel it projects to (cross-view consistency); kept depths are back-projected into
// one coloured cloud.
#include <vector>

#include "d2gs/core/image.hpp"
#include "d2gs/geometry/stereo.hpp"
#include "d2gs/model/point_cloud.hpp"
#include "d2gs/scene/camera.hpp"

namespace d2gs {

struct FusionOptions {
  double relative_tolerance = 0.02;  // |z − z'| / z' for two depths to agree
  int min_consistent_views = 1;      // other views that must agree
  int pixel_stride = 4;              // every stride-th pixel (each axis) becomes a point of the cloud
};

// Per pixel: the mean of the valid candidates that agree (relative tolerance) with their median;
// 0 where no candidate is valid or no more than half agree. All maps must have one size.
DepthMap merge_depth_candidates(const std::vector<const DepthMap*>& candidates, double relative_tolerance);

// Keeps depth[i] at a pixel when the back-projected point, seen from at least `min_consistent_views`
// other views j, has a camera-space z within the tolerance of depth[j] at its pixel there.
std::vector<DepthMap> filter_consistent_depths(const std::vector<const Camera*>& cameras,
                                               const std::vector<DepthMap>& depth, const FusionOptions& options);

// Back-projects every `pixel_stride`-th valid pixel of every view, coloured from that view's image.
PointCloud fuse_depth_maps(const std::vector<const Camera*>& cameras, const std::vector<const Image*>& images,
                           const std::vector<DepthMap>& depth, int pixel_stride);

// World position of pixel (x, y) (integer index, centre at +0.5) at camera-space depth z.
glm::dvec3 backproject(const Camera& camera, int x, int y, double z);

}  // namespace d2gs
