#pragma once
// A coloured point cloud (initial geometry, SfM points, fused stereo).
#include <cstddef>
#include <cstdint>
#include <vector>

#include <glm/glm.hpp>

namespace d2gs {

struct PointCloud {
  std::vector<glm::vec3> positions;
  std::vector<glm::u8vec3> colors;  // RGB 0-255, same length as positions
  std::vector<glm::vec3> normals;   // unit normals, same length as positions, or empty (none known)
  std::size_t size() const { return positions.size(); }
  bool empty() const { return positions.empty(); }
};

// The points at `indices`, in that order, with their colours and (when the cloud has them) normals.
inline PointCloud select_points(const PointCloud& cloud, const std::vector<std::size_t>& indices) {
  PointCloud out;
  const bool normals = !cloud.normals.empty();
  out.positions.reserve(indices.size());
  out.colors.reserve(indices.size());
  if (normals) out.normals.reserve(indices.size());
  for (std::size_t i : indices) {
    out.positions.push_back(cloud.positions[i]);
    out.colors.push_back(cloud.colors[i]);
    if (normals) out.normals.push_back(cloud.normals[i]);
  }
  return out;
}

}  // namespace d2gs
