#pragma once
// A coloured point cloud (initial geometry, SfM points, fused stereo).
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

}  // namespace d2gs
