#pragma once
// PLY files. Gaussian models use the viewer layout of method.md §2: binary little-endian, float
// properties x y z nx ny nz f_dc_0..2 f_rest_0..(3K-1) opacity scale_0..2 rot_0..3, f_rest grouped by
// channel (all red coefficients, then green, then blue), values before activation. The reader matches
// properties by name, accepts missing normals, any SH degree 0..3, extra properties (ignored), ascii and
// big-endian files, and double/other numeric property types. Round trip write → read is bit-exact.
#include <filesystem>

#include "d2gs/model/gaussians.hpp"
#include "d2gs/model/point_cloud.hpp"

namespace d2gs {

void write_gaussians_ply(const std::filesystem::path& path, const Gaussians& model);
Gaussians read_gaussians_ply(const std::filesystem::path& path);
// Parses PLY bytes (the fuzzers' entry point); `source` names the file in errors.
Gaussians parse_gaussians_ply(std::string_view bytes, const std::filesystem::path& source);

// Coloured point clouds: x y z (float) nx ny nz red green blue (uchar), as the 3DGS code writes them.
void write_point_cloud_ply(const std::filesystem::path& path, const PointCloud& cloud);
PointCloud read_point_cloud_ply(const std::filesystem::path& path);
PointCloud parse_point_cloud_ply(std::string_view bytes, const std::filesystem::path& source);

}  // namespace d2gs
