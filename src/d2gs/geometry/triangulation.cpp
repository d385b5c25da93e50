#include "d2gs/geometry/triangulation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <opencv2/core.hpp>

namespace d2gs {

std::optional<glm::dvec2> project_point(const Camera& c, const glm::dvec3& world) {
  const glm::dvec3 p = c.R_world_to_cam * world + c.t_world_to_cam;
  if (!(p.z > 0.0)) return std::nullopt;
  return glm::dvec2(c.fx * p.x / p.z + c.cx, c.fy * p.y / p.z + c.cy);
}

std::optional<glm::dvec3> triangulate_dlt(const std::vector<Observation>& obs) {
  if (obs.size() < 2) return std::nullopt;
  // Rows u·P₃ − P₁ and v·P₃ − P₂ of P = [R | t] with (u, v) the normalised coordinates.
  cv::Mat A(static_cast<int>(obs.size() * 2), 4, CV_64F);
  for (std::size_t i = 0; i < obs.size(); ++i) {
    const Camera& c = *obs[i].camera;
    const double u = (obs[i].pixel.x - c.cx) / c.fx, v = (obs[i].pixel.y - c.cy) / c.fy;
    const glm::dmat3& R = c.R_world_to_cam;
    const glm::dvec3& t = c.t_world_to_cam;
    for (int k = 0; k < 4; ++k) {
      const double p0 = k < 3 ? R[k][0] : t.x, p1 = k < 3 ? R[k][1] : t.y, p2 = k < 3 ? R[k][2] : t.z;
      A.at<double>(static_cast<int>(2 * i), k) = u * p2 - p0;
      A.at<double>(static_cast<int>(2 * i + 1), k) = v * p2 - p1;
    }
  }
  cv::Mat X;
  cv::SVD::solveZ(A, X);
  const double w = X.at<double>(3);
  if (!std::isfinite(w) || std::abs(w) < 1e-12) return std::nullopt;
  const glm::dvec3 x(X.at<double>(0) / w, X.at<double>(1) / w, X.at<double>(2) / w);
  if (!std::isfinite(x.x) || !std::isfinite(x.y) || !std::isfinite(x.z)) return std::nullopt;
  return x;
}

glm::dvec3 refine_point(const std::vector<Observation>& obs, glm::dvec3 x, int iterations) {
  for (int it = 0; it < iterations; ++it) {
    glm::dmat3 JtJ(0.0);
    glm::dvec3 Jtr(0.0);
    bool ok = true;
    for (const auto& o : obs) {
      const Camera& c = *o.camera;
      const glm::dvec3 p = c.R_world_to_cam * x + c.t_world_to_cam;
      if (!(p.z > 0.0)) {
        ok = false;
        break;
      }
      const glm::dvec2 r(c.fx * p.x / p.z + c.cx - o.pixel.x, c.fy * p.y / p.z + c.cy - o.pixel.y);
      // d(pixel)/d(p_cam) then chain with R (rows of the Jacobian w.r.t. x).
      const glm::dvec3 du_dp(c.fx / p.z, 0.0, -c.fx * p.x / (p.z * p.z));
      const glm::dvec3 dv_dp(0.0, c.fy / p.z, -c.fy * p.y / (p.z * p.z));
      const glm::dmat3 Rt = glm::transpose(c.R_world_to_cam);
      const glm::dvec3 ju = Rt * du_dp, jv = Rt * dv_dp;
      JtJ += glm::outerProduct(ju, ju) + glm::outerProduct(jv, jv);
      Jtr += ju * r.x + jv * r.y;
    }
    if (!ok || std::abs(glm::determinant(JtJ)) < 1e-300) break;
    const glm::dvec3 step = glm::inverse(JtJ) * Jtr;
    if (!std::isfinite(step.x) || !std::isfinite(step.y) || !std::isfinite(step.z)) break;
    x -= step;
    if (glm::length(step) < 1e-12 * (1.0 + glm::length(x))) break;
  }
  return x;
}

double max_triangulation_angle_deg(const std::vector<Observation>& obs, const glm::dvec3& x) {
  double best = 0.0;
  for (std::size_t i = 0; i < obs.size(); ++i)
    for (std::size_t j = i + 1; j < obs.size(); ++j) {
      const glm::dvec3 a = glm::normalize(x - obs[i].camera->center_world());
      const glm::dvec3 b = glm::normalize(x - obs[j].camera->center_world());
      best = std::max(best, std::acos(std::clamp(glm::dot(a, b), -1.0, 1.0)));
    }
  return best * 180.0 / M_PI;
}

double mean_reprojection_error(const std::vector<Observation>& obs, const glm::dvec3& x) {
  double sum = 0.0;
  for (const auto& o : obs) {
    const auto p = project_point(*o.camera, x);
    if (!p) return std::numeric_limits<double>::infinity();
    sum += glm::length(*p - o.pixel);
  }
  return obs.empty() ? 0.0 : sum / static_cast<double>(obs.size());
}

TriangulatedPoint triangulate(const std::vector<Observation>& obs, const TriangulationOptions& options) {
  TriangulatedPoint out;
  const auto x0 = triangulate_dlt(obs);
  if (!x0) return out;
  // Cheirality before refinement: a DLT solution behind a camera is a wrong match, not a bad start.
  for (const auto& o : obs) {
    const glm::dvec3 p = o.camera->R_world_to_cam * *x0 + o.camera->t_world_to_cam;
    if (!(p.z > options.min_depth)) {
      out.result = TriangulationResult::BehindCamera;
      return out;
    }
  }
  out.position = refine_point(obs, *x0);
  double worst = 0.0, sum = 0.0;
  for (const auto& o : obs) {
    const glm::dvec3 p = o.camera->R_world_to_cam * out.position + o.camera->t_world_to_cam;
    if (!(p.z > options.min_depth)) {
      out.result = TriangulationResult::BehindCamera;
      return out;
    }
    const double e = glm::length(*project_point(*o.camera, out.position) - o.pixel);
    worst = std::max(worst, e);
    sum += e;
  }
  out.mean_error_px = sum / static_cast<double>(obs.size());
  out.angle_deg = max_triangulation_angle_deg(obs, out.position);
  if (worst > options.max_reprojection_px)
    out.result = TriangulationResult::ReprojectionError;
  else if (out.angle_deg < options.min_angle_deg)
    out.result = TriangulationResult::SmallAngle;
  else
    out.result = TriangulationResult::Ok;
  return out;
}

}  // namespace d2gs
