#pragma once
// NumPy .npy files (format versions 1.0-3.0): little- or big-endian float32/float64/int/uint/bool arrays
// in C or Fortran order are read into row-major doubles; float32 arrays are written. Used for LLFF
// `poses_bounds.npy` and per-view depth maps.
#include <cstddef>
#include <filesystem>
#include <string_view>
#include <vector>

namespace d2gs {

struct NpyArray {
  std::vector<std::size_t> shape;
  std::vector<double> values;  // row-major (C order), whatever the file's order
  std::size_t size() const { return values.size(); }
};

// Parses .npy bytes; `source` names the file in error messages.
NpyArray parse_npy(std::string_view bytes, const std::filesystem::path& source);
NpyArray read_npy(const std::filesystem::path& path);
// Write a float32 / float64 little-endian C-order array atomically.
void write_npy_f32(const std::filesystem::path& path, const std::vector<std::size_t>& shape,
                   const std::vector<float>& values);
void write_npy_f64(const std::filesystem::path& path, const std::vector<std::size_t>& shape,
                   const std::vector<double>& values);

}  // namespace d2gs
