#pragma once
// Multi-view triangulation with known cameras: linear DLT on the normalised image coordinates, then
// Gauss-Newton refinement of the pixel reprojection error, then the filters of SfM (cheirality,
// reprojection error, triangulation angle).
#include <optional>
#include <vector>

#include <glm/glm.hpp>

#include "d2gs/scene/camera.hpp"

namespace d2gs {

struct Observation {
  const Camera* camera = nullptr;
  glm::dvec2 pixel{0.0};  // Camera pixel convention (centres at +0.5)
};

// Projection of a world point to pixels; nullopt when it is not in front of the camera (z ≤ 0).
std::optional<glm::dvec2> project_point(const Camera& camera, const glm::dvec3& world);

// Linear (DLT) triangulation of ≥ 2 observations; nullopt when the system is degenerate.
std::optional<glm::dvec3> triangulate_dlt(const std::vector<Observation>& obs);
// A few Gauss-Newton steps on the sum of squared pixel reprojection errors, starting from `x`.
glm::dvec3 refine_point(const std::vector<Observation>& obs, glm::dvec3 x, int iterations = 5);

// Largest angle (degrees) between the viewing rays of any two observations.
double max_triangulation_angle_deg(const std::vector<Observation>& obs, const glm::dvec3& x);
// Mean pixel reprojection error; infinity when the point is behind any camera.
double mean_reprojection_error(const std::vector<Observation>& obs, const glm::dvec3& x);

struct TriangulationOptions {
  double max_reprojection_px = 2.0;  // every observation within this error
  double min_angle_deg = 1.0;        // largest pairwise ray angle at least this
  double min_depth = 1e-6;           // cheirality: camera-space z above this in every view
};

enum class TriangulationResult { Ok, Degenerate, BehindCamera, ReprojectionError, SmallAngle };

struct TriangulatedPoint {
  glm::dvec3 position{0.0};
  double mean_error_px = 0.0;
  double angle_deg = 0.0;
  TriangulationResult result = TriangulationResult::Degenerate;
};

// DLT + refinement + filters; result says which filter (if any) rejected the point.
TriangulatedPoint triangulate(const std::vector<Observation>& obs, const TriangulationOptions& options);

}  // namespace d2gs
