#pragma once
// Rectified two-view stereo between two posed views: OpenCV stereoRectify (poses known, no distortion),
// semi-global matching (StereoSGBM) on the rectified pair, and the disparities turned back into depth
// maps of the two original views (camera-space z, 0 = no depth). Vertical baselines are handled by
// transposing the rectified pair; the second view's disparity comes from the mirrored pair.
#include <vector>

#include "d2gs/core/image.hpp"
#include "d2gs/scene/camera.hpp"

namespace d2gs {

struct DepthMap {
  int width = 0, height = 0;
  std::vector<float> depth;  // row-major, camera-space z; 0 = invalid
  float at(int x, int y) const { return depth[static_cast<std::size_t>(y) * width + x]; }
  std::size_t valid_count() const;
};

struct StereoOptions {
  int block_size = 5;          // SGBM matching block (odd)
  int uniqueness_ratio = 10;   // SGBM uniqueness margin, percent
  int speckle_window = 100;    // SGBM speckle filter: region size (pixels) ...
  int speckle_range = 2;       // ... and disparity variation inside it
  int max_disparities = 256;   // cap on the disparity search range
};

struct StereoPairDepth {
  DepthMap depth_a, depth_b;
  double baseline = 0.0;            // distance between the camera centres
  int min_disparity = 0, num_disparities = 0;
};

// Depth maps of both views from their rectified pair. [near, far] is the expected depth range (e.g. from
// the sparse points), used to choose SGBM's disparity range; throws d2gs::Error for coincident cameras.
StereoPairDepth stereo_pair_depth(const Camera& cam_a, const Image& image_a, const Camera& cam_b, const Image& image_b,
                                  double near, double far, const StereoOptions& options = {});

}  // namespace d2gs
