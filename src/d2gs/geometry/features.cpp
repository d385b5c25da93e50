#include "d2gs/geometry/features.hpp"

#include <algorithm>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "d2gs/core/error.hpp"

namespace d2gs {

cv::Mat to_gray_u8(const Image& image);  // geometry/stereo.cpp

ViewFeatures detect_sift(const Image& image, int max_features, double contrast_threshold) {
  if (image.empty()) fail("SIFT: empty image");
  const cv::Mat gray = to_gray_u8(image);
  auto sift = cv::SIFT::create(std::max(0, max_features), 3, contrast_threshold);
  std::vector<cv::KeyPoint> kps;
  cv::Mat desc;
  sift->detectAndCompute(gray, cv::noArray(), kps, desc);
  ViewFeatures f;
  f.keypoints.reserve(kps.size());
  for (const auto& k : kps) f.keypoints.emplace_back(k.pt.x + 0.5, k.pt.y + 0.5);  // OpenCV: centre at integer
  if (!kps.empty()) {
    cv::Mat d32;
    desc.convertTo(d32, CV_32F);
    f.descriptors.assign(d32.ptr<float>(0), d32.ptr<float>(0) + d32.total());
  }
  return f;
}

}  // namespace d2gs
