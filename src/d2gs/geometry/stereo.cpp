#include "d2gs/geometry/stereo.hpp"

#include <algorithm>
#include <cmath>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "d2gs/core/error.hpp"

namespace d2gs {

cv::Mat to_gray_u8(const Image& image) {
  cv::Mat gray(image.height, image.width, CV_8U);
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) {
      double v;
      if (image.channels >= 3)
        v = 0.299 * image.at(x, y, 0) + 0.587 * image.at(x, y, 1) + 0.114 * image.at(x, y, 2);
      else
        v = image.at(x, y, 0);
      gray.at<std::uint8_t>(y, x) = static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0, 1.0) * 255.0));
    }
  return gray;
}

std::size_t DepthMap::valid_count() const {
  return static_cast<std::size_t>(std::count_if(depth.begin(), depth.end(), [](float d) { return d > 0.0f; }));
}

namespace {

// OpenCV's pixel convention has pixel centres at integers: c_cv = c − 0.5.
cv::Mat camera_matrix_cv(const Camera& c) {
  return (cv::Mat_<double>(3, 3) << c.fx, 0, c.cx - 0.5, 0, c.fy, c.cy - 0.5, 0, 0, 1);
}
cv::Mat to_cv(const glm::dmat3& m) {
  cv::Mat out(3, 3, CV_64F);
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) out.at<double>(r, c) = m[c][r];
  return out;
}

// Disparity (float pixels, NaN = none) of `left` against `right`, with d = x_left − x_right.
cv::Mat sgbm(const cv::Mat& left, const cv::Mat& right, int min_disp, int num_disp, const StereoOptions& o) {
  const int bs = o.block_size;
  auto matcher = cv::StereoSGBM::create(min_disp, num_disp, bs, 8 * bs * bs, 32 * bs * bs, 1, 0, o.uniqueness_ratio,
                                        o.speckle_window, o.speckle_range, cv::StereoSGBM::MODE_SGBM_3WAY);
  // SGBM leaves the first min + num columns of the left image without a disparity (their match would
  // lie outside the right image); padding both images on the left keeps those columns.
  const int pad = std::max(0, min_disp + num_disp);
  cv::Mat lp, rp, raw;
  cv::copyMakeBorder(left, lp, 0, 0, pad, 0, cv::BORDER_CONSTANT, 0);
  cv::copyMakeBorder(right, rp, 0, 0, pad, 0, cv::BORDER_CONSTANT, 0);
  matcher->compute(lp, rp, raw);
  cv::Mat disp(left.size(), CV_32F);
  for (int y = 0; y < disp.rows; ++y)
    for (int x = 0; x < disp.cols; ++x) {
      const short v = raw.at<short>(y, x + pad);
      disp.at<float>(y, x) = v < min_disp * 16 ? NAN : static_cast<float>(v) / 16.0f;
    }
  return disp;
}

// Depth of every original pixel of a camera from the disparity map of its rectified image: the pixel's
// ray is rotated into the rectified frame (R_rect), looked up in the disparity map (nearest), and its
// rectified depth f·B/d converted back to the camera's own z.
DepthMap depth_from_disparity(const Camera& cam, const cv::Mat& R_rect, const cv::Mat& P_rect, const cv::Mat& disp,
                              double baseline_rect) {
  DepthMap out;
  out.width = cam.width;
  out.height = cam.height;
  out.depth.assign(static_cast<std::size_t>(cam.width) * cam.height, 0.0f);
  const double f = P_rect.at<double>(0, 0), pcx = P_rect.at<double>(0, 2), pcy = P_rect.at<double>(1, 2);
  cv::Matx33d R;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) R(r, c) = R_rect.at<double>(r, c);
  for (int y = 0; y < cam.height; ++y)
    for (int x = 0; x < cam.width; ++x) {
      // ray through the pixel centre (OpenCV convention x, y ↔ d2gs x + 0.5, y + 0.5), camera z = 1
      const cv::Vec3d ray((x + 0.5 - cam.cx) / cam.fx, (y + 0.5 - cam.cy) / cam.fy, 1.0);
      const cv::Vec3d rr = R * ray;
      if (!(rr[2] > 1e-9)) continue;
      const int u = static_cast<int>(std::lround(f * rr[0] / rr[2] + pcx));
      const int v = static_cast<int>(std::lround(f * rr[1] / rr[2] + pcy));
      if (u < 0 || v < 0 || u >= disp.cols || v >= disp.rows) continue;
      const float d = disp.at<float>(v, u);
      if (!(d > 0.0f)) continue;
      const double z_rect = f * baseline_rect / d;
      out.depth[static_cast<std::size_t>(y) * cam.width + x] = static_cast<float>(z_rect / rr[2]);
    }
  return out;
}

}  // namespace

StereoPairDepth stereo_pair_depth(const Camera& cam_a, const Image& image_a, const Camera& cam_b, const Image& image_b,
                                  double near, double far, const StereoOptions& options) {
  if (cam_a.width != cam_b.width || cam_a.height != cam_b.height)
    fail("stereo: {} and {} differ in size", cam_a.image_name, cam_b.image_name);
  if (options.block_size < 1 || options.block_size % 2 == 0) fail("stereo: block size must be odd, got {}", options.block_size);
  const glm::dmat3 Rab = cam_b.R_world_to_cam * glm::transpose(cam_a.R_world_to_cam);
  const glm::dvec3 tab = cam_b.t_world_to_cam - Rab * cam_a.t_world_to_cam;
  StereoPairDepth out;
  out.baseline = glm::length(tab);
  if (!(out.baseline > 0.0)) fail("stereo: {} and {} share their camera centre", cam_a.image_name, cam_b.image_name);
  const cv::Size size(cam_a.width, cam_a.height);
  const cv::Mat Ka = camera_matrix_cv(cam_a), Kb = camera_matrix_cv(cam_b), D = cv::Mat::zeros(1, 5, CV_64F);
  const cv::Mat R = to_cv(Rab), T = (cv::Mat_<double>(3, 1) << tab.x, tab.y, tab.z);
  cv::Mat R1, R2, P1, P2, Q;
  cv::stereoRectify(Ka, D, Kb, D, size, R, T, R1, R2, P1, P2, Q, cv::CALIB_ZERO_DISPARITY, -1, size);
  const bool vertical = std::abs(P2.at<double>(1, 3)) > std::abs(P2.at<double>(0, 3));
  const double f = P1.at<double>(0, 0);
  const double shift = (vertical ? P2.at<double>(1, 3) : P2.at<double>(0, 3)) / f;  // signed baseline
  const double baseline = std::abs(shift);
  cv::Mat m1x, m1y, m2x, m2y, ra, rb;
  cv::initUndistortRectifyMap(Ka, D, R1, P1, size, CV_32FC1, m1x, m1y);
  cv::initUndistortRectifyMap(Kb, D, R2, P2, size, CV_32FC1, m2x, m2y);
  cv::remap(to_gray_u8(image_a), ra, m1x, m1y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
  cv::remap(to_gray_u8(image_b), rb, m2x, m2y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, 0);
  if (vertical) {
    cv::transpose(ra, ra);
    cv::transpose(rb, rb);
  }
  // shift < 0: b lies along +x (or +y) of a in the rectified frame, so a is the left image.
  const bool a_left = shift < 0;
  const cv::Mat& left = a_left ? ra : rb;
  const cv::Mat& right = a_left ? rb : ra;
  // Disparity range from the expected depths, with a margin.
  near = std::max(near, 1e-9);
  far = std::max(far, near * 1.01);
  const double d_lo = f * baseline / far * 0.8, d_hi = f * baseline / near * 1.25;
  out.min_disparity = std::max(0, static_cast<int>(std::floor(d_lo)));
  out.num_disparities = std::clamp(16 * static_cast<int>(std::ceil((d_hi - out.min_disparity) / 16.0)), 16,
                                   std::max(16, options.max_disparities / 16 * 16));
  cv::Mat disp_left = sgbm(left, right, out.min_disparity, out.num_disparities, options);
  cv::Mat fl, fr, disp_right;
  cv::flip(left, fl, 1);
  cv::flip(right, fr, 1);
  cv::flip(sgbm(fr, fl, out.min_disparity, out.num_disparities, options), disp_right, 1);
  // Left-right consistency: a left pixel's match in the right image must map back within 1 pixel.
  for (int y = 0; y < disp_left.rows; ++y)
    for (int x = 0; x < disp_left.cols; ++x) {
      const float d = disp_left.at<float>(y, x);
      if (!(d > 0.0f)) continue;
      const int xr = static_cast<int>(std::lround(x - d));
      if (xr < 0 || xr >= disp_right.cols || !(std::abs(disp_right.at<float>(y, xr) - d) <= 1.0f))
        disp_left.at<float>(y, x) = NAN;
    }
  if (vertical) {
    cv::transpose(disp_left, disp_left);
    cv::transpose(disp_right, disp_right);
  }
  const cv::Mat& disp_a = a_left ? disp_left : disp_right;
  const cv::Mat& disp_b = a_left ? disp_right : disp_left;
  out.depth_a = depth_from_disparity(cam_a, R1, P1, disp_a, baseline);
  out.depth_b = depth_from_disparity(cam_b, R2, P2, disp_b, baseline);
  return out;
}

}  // namespace d2gs
