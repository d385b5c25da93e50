#pragma once
// SIFT features of one view (OpenCV's cv::SIFT). Keypoints are in d2gs pixel coordinates (pixel centres
// at integer + 0.5, as the cameras' intrinsics); descriptors are 128 floats per keypoint, row-major.
#include <vector>

#include <glm/glm.hpp>

#include "d2gs/core/image.hpp"

namespace d2gs {

struct ViewFeatures {
  std::vector<glm::dvec2> keypoints;  // pixel position, centre convention of Camera
  std::vector<float> descriptors;     // keypoints.size() × 128
  std::size_t size() const { return keypoints.size(); }
};

inline constexpr int kSiftDescriptorSize = 128;

// Detects up to `max_features` SIFT keypoints (strongest first) on the grey version of `image`
// (RGB float [0,1]); `contrast_threshold` is SIFT's (OpenCV default 0.04; lower finds more keypoints in
// weak texture). Deterministic for a given image.
ViewFeatures detect_sift(const Image& image, int max_features = 8000, double contrast_threshold = 0.04);

}  // namespace d2gs
