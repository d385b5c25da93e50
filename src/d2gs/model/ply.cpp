#include "d2gs/model/ply.hpp"

#include "d2gs/core/error.hpp"

namespace d2gs {
void write_gaussians_ply(const std::filesystem::path& path, const Gaussians&) { fail_file(path, "not implemented yet"); }
Gaussians read_gaussians_ply(const std::filesystem::path& path) { fail_file(path, "not implemented yet"); }
Gaussians parse_gaussians_ply(std::string_view, const std::filesystem::path& path) { fail_file(path, "not implemented yet"); }
void write_point_cloud_ply(const std::filesystem::path& path, const PointCloud&) { fail_file(path, "not implemented yet"); }
PointCloud read_point_cloud_ply(const std::filesystem::path& path) { fail_file(path, "not implemented yet"); }
PointCloud parse_point_cloud_ply(std::string_view, const std::filesystem::path& path) { fail_file(path, "not implemented yet"); }
}  // namespace d2gs
