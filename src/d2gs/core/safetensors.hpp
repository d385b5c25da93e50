#pragma once
// safetensors files (the format of Hugging Face's `safetensors`): an 8-byte little-endian header
// length N, N bytes of JSON mapping each tensor name to {"dtype", "shape", "data_offsets": [begin, end]}
// (offsets into the byte buffer that follows the header) and an optional "__metadata__" object of
// strings, then the raw little-endian tensor bytes in C order. d2gs reads F32, F64 and F16 tensors into
// float32 and writes F32. Used for LPIPS weights (docs/formats.md).
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <vector>

namespace d2gs {

struct Tensor {
  std::vector<std::int64_t> shape;
  std::vector<float> values;  // row-major (C order)
  std::size_t numel() const { return values.size(); }
};

struct TensorFile {
  std::map<std::string, Tensor> tensors;
  std::map<std::string, std::string> metadata;  // the "__metadata__" object, if any
};

// Parses safetensors bytes; `source` names the file in error messages. Rejects truncated or
// overlapping data, unknown dtypes, sizes that do not match shapes and a malformed header.
TensorFile parse_safetensors(std::string_view bytes, const std::filesystem::path& source);
TensorFile read_safetensors(const std::filesystem::path& path);
// Serialises as F32 tensors (names in sorted order, data packed in that order).
std::string serialize_safetensors(const TensorFile& file);
// Writes atomically.
void write_safetensors(const std::filesystem::path& path, const TensorFile& file);

}  // namespace d2gs
