#include "d2gs/geometry/matching.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/features2d.hpp>

namespace d2gs {

namespace {
glm::dmat3 skew(const glm::dvec3& v) {
  // columns of [v]×
  return glm::dmat3(glm::dvec3(0, v.z, -v.y), glm::dvec3(-v.z, 0, v.x), glm::dvec3(v.y, -v.x, 0));
}
glm::dmat3 intrinsics(const Camera& c) {
  glm::dmat3 K(1.0);
  K[0][0] = c.fx;
  K[1][1] = c.fy;
  K[2][0] = c.cx;
  K[2][1] = c.cy;
  return K;
}
cv::Mat descriptor_mat(const ViewFeatures& f) {
  return cv::Mat(static_cast<int>(f.size()), kSiftDescriptorSize, CV_32F, const_cast<float*>(f.descriptors.data()));
}
}  // namespace

glm::dmat3 fundamental_from_cameras(const Camera& a, const Camera& b) {
  // x_b_cam = R·x_a_cam + t with R = R_b·R_aᵀ, t = t_b − R·t_a; E = [t]×·R; F = K_b⁻ᵀ·E·K_a⁻¹.
  const glm::dmat3 R = b.R_world_to_cam * glm::transpose(a.R_world_to_cam);
  const glm::dvec3 t = b.t_world_to_cam - R * a.t_world_to_cam;
  const glm::dmat3 E = skew(t) * R;
  return glm::transpose(glm::inverse(intrinsics(b))) * E * glm::inverse(intrinsics(a));
}

double epipolar_distance(const glm::dmat3& F, const glm::dvec2& xa, const glm::dvec2& xb) {
  const glm::dvec3 pa(xa, 1.0), pb(xb, 1.0);
  const glm::dvec3 line_b = F * pa;                   // in image b
  const glm::dvec3 line_a = glm::transpose(F) * pb;   // in image a
  const double r = glm::dot(pb, line_b);              // = pa · line_a
  const double nb = std::hypot(line_b.x, line_b.y), na = std::hypot(line_a.x, line_a.y);
  if (nb == 0.0 || na == 0.0) return std::abs(r) == 0.0 ? 0.0 : INFINITY;
  return std::max(std::abs(r) / nb, std::abs(r) / na);
}

std::vector<FeatureMatch> match_descriptors(const ViewFeatures& a, const ViewFeatures& b, const MatchOptions& options) {
  std::vector<FeatureMatch> out;
  if (a.size() < 2 || b.size() < 2) return out;
  cv::BFMatcher matcher(cv::NORM_L2, false);
  const cv::Mat da = descriptor_mat(a), db = descriptor_mat(b);
  std::vector<std::vector<cv::DMatch>> ab, ba;
  matcher.knnMatch(da, db, ab, 2);
  std::vector<int> best_ba(b.size(), -1);
  if (options.mutual) {
    matcher.knnMatch(db, da, ba, 1);
    for (const auto& m : ba)
      if (!m.empty()) best_ba[static_cast<std::size_t>(m[0].queryIdx)] = m[0].trainIdx;
  }
  for (const auto& m : ab) {
    if (m.size() < 2) continue;
    if (!(m[0].distance < options.ratio * m[1].distance)) continue;
    if (options.mutual && best_ba[static_cast<std::size_t>(m[0].trainIdx)] != m[0].queryIdx) continue;
    out.push_back({m[0].queryIdx, m[0].trainIdx});
  }
  return out;
}

std::vector<FeatureMatch> match_guided(const ViewFeatures& a, const ViewFeatures& b, const Camera& cam_a,
                                       const Camera& cam_b, const MatchOptions& options, double max_distance_px) {
  const glm::dmat3 F = fundamental_from_cameras(cam_a, cam_b);
  const std::size_t na = a.size(), nb = b.size();
  constexpr float kNone = std::numeric_limits<float>::infinity();
  // Best and second-best squared descriptor distances in each direction, among epipolar candidates.
  struct Best {
    float d1 = kNone, d2 = kNone;
    int index = -1;
    void offer(float d, int i) {
      if (d < d1) d2 = d1, d1 = d, index = i;
      else if (d < d2) d2 = d;
    }
  };
  std::vector<Best> best_a(na), best_b(nb);
  const auto sq = [](const float* x, const float* y) {
    float s = 0.0f;
    for (int k = 0; k < kSiftDescriptorSize; ++k) {
      const float t = x[k] - y[k];
      s += t * t;
    }
    return s;
  };
  for (std::size_t i = 0; i < na; ++i) {
    const glm::dvec3 line = F * glm::dvec3(a.keypoints[i], 1.0);  // in image b
    const double norm = std::hypot(line.x, line.y);
    if (norm == 0.0) continue;
    for (std::size_t j = 0; j < nb; ++j) {
      if (std::abs(glm::dot(line, glm::dvec3(b.keypoints[j], 1.0))) > max_distance_px * norm) continue;
      if (epipolar_distance(F, a.keypoints[i], b.keypoints[j]) > max_distance_px) continue;
      const float d = sq(a.descriptors.data() + i * kSiftDescriptorSize, b.descriptors.data() + j * kSiftDescriptorSize);
      best_a[i].offer(d, static_cast<int>(j));
      best_b[j].offer(d, static_cast<int>(i));
    }
  }
  const float ratio2 = static_cast<float>(options.ratio * options.ratio);
  std::vector<FeatureMatch> out;
  for (std::size_t i = 0; i < na; ++i) {
    const Best& ba = best_a[i];
    if (ba.index < 0 || !(ba.d1 < ratio2 * ba.d2)) continue;  // a single candidate passes (d2 = ∞)
    if (options.mutual && best_b[static_cast<std::size_t>(ba.index)].index != static_cast<int>(i)) continue;
    out.push_back({static_cast<int>(i), ba.index});
  }
  return out;
}

std::vector<FeatureMatch> filter_epipolar(const std::vector<FeatureMatch>& matches, const ViewFeatures& a,
                                          const ViewFeatures& b, const Camera& cam_a, const Camera& cam_b,
                                          double max_distance_px) {
  const glm::dmat3 F = fundamental_from_cameras(cam_a, cam_b);
  std::vector<FeatureMatch> out;
  for (const auto& m : matches)
    if (epipolar_distance(F, a.keypoints[static_cast<std::size_t>(m.a)], b.keypoints[static_cast<std::size_t>(m.b)]) <=
        max_distance_px)
      out.push_back(m);
  return out;
}

}  // namespace d2gs
