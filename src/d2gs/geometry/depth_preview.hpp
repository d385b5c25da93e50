#pragma once
// Pictures of depth maps for people to look at (`d2gs init` writes one per view beside the .npy): inverse
// depth through the turbo colour map, near in red, far in blue, pixels without a depth black. One range for
// all views of a geometry, so that the same colour is the same depth in each.
#include <utility>
#include <vector>

#include "d2gs/core/image.hpp"
#include "d2gs/geometry/stereo.hpp"

namespace d2gs {

// The inverse depths at the 2nd and 98th percentiles of all valid pixels of `maps` (so that a few outliers
// do not wash the pictures out); {0, 0} when no pixel has a depth.
std::pair<double, double> inverse_depth_range(const std::vector<DepthMap>& maps);

// RGB [0, 1], the map's size: turbo((1/z − lo) / (hi − lo)) clamped to [0, 1]; black where z ≤ 0.
Image depth_preview(const DepthMap& map, std::pair<double, double> inverse_range);

}  // namespace d2gs
