#include "d2gs/core/safetensors.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>

#include <nlohmann/json.hpp>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"

namespace d2gs {
namespace {

static_assert(std::endian::native == std::endian::little, "safetensors I/O assumes a little-endian host");

std::uint64_t read_u64_le(const char* p) {
  std::uint64_t v = 0;
  std::memcpy(&v, p, 8);
  return v;
}

// IEEE half to float (subnormals, infinities and NaN included).
float half_to_float(std::uint16_t h) {
  const std::uint32_t sign = (h >> 15) & 1u, exponent = (h >> 10) & 0x1fu, mantissa = h & 0x3ffu;
  float v;
  if (exponent == 0) v = std::ldexp(static_cast<float>(mantissa), -24);
  else if (exponent == 31) v = mantissa ? std::numeric_limits<float>::quiet_NaN() : std::numeric_limits<float>::infinity();
  else v = std::ldexp(static_cast<float>(mantissa | 0x400u), static_cast<int>(exponent) - 25);
  return sign ? -v : v;
}

std::size_t dtype_size(const std::string& dtype) {
  if (dtype == "F32") return 4;
  if (dtype == "F64") return 8;
  if (dtype == "F16") return 2;
  return 0;
}

}  // namespace

TensorFile parse_safetensors(std::string_view bytes, const std::filesystem::path& source) {
  if (bytes.size() < 8) fail_file(source, "not a safetensors file ({} bytes, too short for the header length)", bytes.size());
  const std::uint64_t header_len = read_u64_le(bytes.data());
  if (header_len > bytes.size() - 8)
    fail_file(source, "not a safetensors file (header length {} exceeds the file size {})", header_len, bytes.size());
  const std::string_view header = bytes.substr(8, static_cast<std::size_t>(header_len));
  const std::string_view data = bytes.substr(8 + static_cast<std::size_t>(header_len));
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(header);
  } catch (const nlohmann::json::exception&) {  // parse_error, or out_of_range for a number like 1e400
    fail_file(source, "not a safetensors file (the header is not JSON)");
  }
  if (!j.is_object()) fail_file(source, "safetensors header is not a JSON object");
  TensorFile out;
  struct Span {
    std::uint64_t begin, end;
    std::string name;
  };
  std::vector<Span> spans;
  for (const auto& [name, entry] : j.items()) {
    if (name == "__metadata__") {
      if (!entry.is_object()) fail_file(source, "__metadata__ is not an object");
      for (const auto& [k, v] : entry.items())
        out.metadata[k] = v.is_string() ? v.get<std::string>() : v.dump();
      continue;
    }
    if (!entry.is_object() || !entry.contains("dtype") || !entry.contains("shape") || !entry.contains("data_offsets"))
      fail_file(source, "tensor '{}': expected dtype, shape and data_offsets", name);
    const auto& dt = entry["dtype"];
    const auto& sh = entry["shape"];
    const auto& off = entry["data_offsets"];
    if (!dt.is_string()) fail_file(source, "tensor '{}': dtype is not a string", name);
    const std::string dtype = dt.get<std::string>();
    const std::size_t elem = dtype_size(dtype);
    if (elem == 0) fail_file(source, "tensor '{}': unsupported dtype {} (F32, F64 or F16)", name, dtype);
    if (!sh.is_array()) fail_file(source, "tensor '{}': shape is not an array", name);
    Tensor t;
    std::uint64_t numel = 1;
    for (const auto& d : sh) {
      if (!d.is_number_integer() || d.get<std::int64_t>() < 0) fail_file(source, "tensor '{}': bad shape {}", name, sh.dump());
      const auto n = d.get<std::int64_t>();
      t.shape.push_back(n);
      if (n != 0 && numel > std::numeric_limits<std::uint64_t>::max() / static_cast<std::uint64_t>(n))
        fail_file(source, "tensor '{}': shape {} overflows", name, sh.dump());
      numel *= static_cast<std::uint64_t>(n);
    }
    if (!off.is_array() || off.size() != 2 || !off[0].is_number_unsigned() || !off[1].is_number_unsigned())
      fail_file(source, "tensor '{}': data_offsets must be two non-negative integers", name);
    const auto begin = off[0].get<std::uint64_t>(), end = off[1].get<std::uint64_t>();
    if (begin > end || end > data.size())
      fail_file(source, "tensor '{}': data [{}, {}) lies outside the {} data bytes (truncated file?)", name, begin, end, data.size());
    if (numel > std::numeric_limits<std::uint64_t>::max() / elem || end - begin != numel * elem)
      fail_file(source, "tensor '{}': {} data bytes for shape {} of {} ({} expected)", name, end - begin, sh.dump(), dtype,
                numel * elem);
    t.values.resize(static_cast<std::size_t>(numel));
    const char* p = data.data() + begin;
    for (std::size_t i = 0; i < t.values.size(); ++i) {
      if (dtype == "F32") std::memcpy(&t.values[i], p + 4 * i, 4);
      else if (dtype == "F64") {
        double v;
        std::memcpy(&v, p + 8 * i, 8);
        t.values[i] = static_cast<float>(v);
      } else {
        std::uint16_t h;
        std::memcpy(&h, p + 2 * i, 2);
        t.values[i] = half_to_float(h);
      }
    }
    spans.push_back({begin, end, name});
    out.tensors.emplace(name, std::move(t));
  }
  std::sort(spans.begin(), spans.end(), [](const Span& a, const Span& b) { return a.begin < b.begin; });
  for (std::size_t i = 1; i < spans.size(); ++i)
    if (spans[i].begin < spans[i - 1].end)
      fail_file(source, "tensors '{}' and '{}' overlap", spans[i - 1].name, spans[i].name);
  return out;
}

TensorFile read_safetensors(const std::filesystem::path& path) { return parse_safetensors(read_file(path), path); }

std::string serialize_safetensors(const TensorFile& file) {
  nlohmann::json header = nlohmann::json::object();
  if (!file.metadata.empty()) header["__metadata__"] = file.metadata;
  std::uint64_t offset = 0;
  for (const auto& [name, t] : file.tensors) {
    const std::uint64_t bytes = 4 * static_cast<std::uint64_t>(t.values.size());
    header[name] = {{"dtype", "F32"}, {"shape", t.shape}, {"data_offsets", {offset, offset + bytes}}};
    offset += bytes;
  }
  std::string h = header.dump();
  while ((8 + h.size()) % 8 != 0) h.push_back(' ');  // the format pads the header with spaces to 8-byte alignment
  std::string out(8, '\0');
  const std::uint64_t len = h.size();
  std::memcpy(out.data(), &len, 8);
  out += h;
  for (const auto& [name, t] : file.tensors)
    out.append(reinterpret_cast<const char*>(t.values.data()), 4 * t.values.size());
  return out;
}

void write_safetensors(const std::filesystem::path& path, const TensorFile& file) {
  write_file_atomic(path, serialize_safetensors(file));
}

}  // namespace d2gs
