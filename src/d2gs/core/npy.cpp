#include "d2gs/core/npy.hpp"

#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"

namespace d2gs {
namespace {

// Finds `'key': value` in the header dictionary and returns the value text (without trailing comma).
std::string dict_value(std::string_view header, std::string_view key, const std::filesystem::path& src) {
  const std::string needle = fmt::format("'{}'", key);
  const auto k = header.find(needle);
  if (k == std::string_view::npos) fail_file(src, "npy header has no '{}'", key);
  auto p = header.find(':', k + needle.size());
  if (p == std::string_view::npos) fail_file(src, "npy header is malformed");
  ++p;
  while (p < header.size() && header[p] == ' ') ++p;
  std::size_t end = p;
  if (p < header.size() && header[p] == '(') {
    end = header.find(')', p);
    if (end == std::string_view::npos) fail_file(src, "npy header shape is malformed");
    ++end;
  } else if (p < header.size() && header[p] == '\'') {
    end = header.find('\'', p + 1);
    if (end == std::string_view::npos) fail_file(src, "npy header is malformed");
    ++end;
  } else {
    while (end < header.size() && header[end] != ',' && header[end] != '}') ++end;
  }
  return std::string(header.substr(p, end - p));
}

std::vector<std::size_t> parse_shape(const std::string& text, const std::filesystem::path& src) {
  std::vector<std::size_t> shape;
  std::size_t i = 1;  // skip '('
  while (i < text.size()) {
    while (i < text.size() && (text[i] == ' ' || text[i] == ',')) ++i;
    if (i >= text.size() || text[i] == ')') break;
    if (text[i] < '0' || text[i] > '9') fail_file(src, "npy shape {} is malformed", text);
    std::size_t v = 0;
    while (i < text.size() && text[i] >= '0' && text[i] <= '9') {
      if (v > (std::numeric_limits<std::size_t>::max() - 9) / 10) fail_file(src, "npy shape overflows");
      v = v * 10 + static_cast<std::size_t>(text[i] - '0');
      ++i;
    }
    shape.push_back(v);
  }
  return shape;
}

template <typename T>
T load_scalar(const char* p, bool swap) {
  T v;
  std::memcpy(&v, p, sizeof(T));
  if (swap) {
    unsigned char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
    std::memcpy(&v, b, sizeof(T));
  }
  return v;
}

}  // namespace

NpyArray parse_npy(std::string_view bytes, const std::filesystem::path& src) {
  static constexpr char magic[] = "\x93NUMPY";
  if (bytes.size() < 10 || bytes.substr(0, 6) != std::string_view(magic, 6))
    fail_file(src, "not a .npy file (bad magic)");
  const auto major = static_cast<unsigned char>(bytes[6]);
  std::size_t header_len = 0, header_start = 0;
  if (major == 1) {
    header_len = static_cast<unsigned char>(bytes[8]) | (static_cast<unsigned char>(bytes[9]) << 8);
    header_start = 10;
  } else if (major == 2 || major == 3) {
    if (bytes.size() < 12) fail_file(src, "truncated .npy header");
    header_len = 0;
    for (int i = 3; i >= 0; --i) header_len = (header_len << 8) | static_cast<unsigned char>(bytes[8 + i]);
    header_start = 12;
  } else {
    fail_file(src, "unsupported .npy format version {}", major);
  }
  if (header_start + header_len > bytes.size()) fail_file(src, "truncated .npy header");
  const std::string_view header = bytes.substr(header_start, header_len);
  const std::string descr = dict_value(header, "descr", src);
  const std::string order = dict_value(header, "fortran_order", src);
  const auto shape = parse_shape(dict_value(header, "shape", src), src);

  if (descr.size() < 5 || descr.front() != '\'') fail_file(src, "npy dtype {} is malformed", descr);
  const char endian = descr[1];
  const char kind = descr[2];
  const std::string width_text = descr.substr(3, descr.size() - 4);
  if (width_text.empty() || width_text.size() > 2 ||
      !std::all_of(width_text.begin(), width_text.end(), [](char ch) { return ch >= '0' && ch <= '9'; }))
    fail_file(src, "npy dtype {} is not supported", descr);
  const int width = std::stoi(width_text);
  const bool little_host = std::endian::native == std::endian::little;
  const bool swap = (endian == '>' && little_host) || (endian == '<' && !little_host);
  if (endian != '<' && endian != '>' && endian != '|' && endian != '=')
    fail_file(src, "npy dtype {} is not supported", descr);
  // Every supported dtype has a width of 1, 2, 4 or 8 bytes; checked before the size arithmetic, where a
  // zero width ('|u0', found by fuzz_npy) made any element count look present in zero bytes.
  const bool supported = (kind == 'f' && (width == 4 || width == 8)) ||
                         ((kind == 'i' || kind == 'u') && (width == 1 || width == 2 || width == 4 || width == 8)) ||
                         (kind == 'b' && width == 1);
  if (!supported) fail_file(src, "npy dtype {} is not supported", descr);

  std::size_t count = 1;
  for (auto d : shape) {
    if (d != 0 && count > std::numeric_limits<std::size_t>::max() / 16 / d) fail_file(src, "npy shape too large");
    count *= d;
  }
  const std::size_t data_start = header_start + header_len;
  const std::size_t need = count * static_cast<std::size_t>(width);
  if (bytes.size() - data_start < need)
    fail_file(src, "truncated .npy data: {} bytes for {} values of {} bytes", bytes.size() - data_start,
              count, width);
  // numpy writes nothing after the data: more bytes than the header's shape holds are a damaged file (or a
  // header whose shape was edited), not something to ignore.
  if (bytes.size() - data_start > need)
    fail_file(src, "{} unexpected bytes after the .npy data (the header's shape holds {} values of {} bytes)",
              bytes.size() - data_start - need, count, width);

  NpyArray out;
  out.shape = shape;
  out.values.resize(count);
  const char* data = bytes.data() + data_start;
  for (std::size_t i = 0; i < count; ++i) {
    const char* p = data + i * static_cast<std::size_t>(width);
    double v = 0;
    if (kind == 'f' && width == 4) v = load_scalar<float>(p, swap);
    else if (kind == 'f' && width == 8) v = load_scalar<double>(p, swap);
    else if (kind == 'i' && width == 1) v = load_scalar<std::int8_t>(p, false);
    else if (kind == 'i' && width == 2) v = load_scalar<std::int16_t>(p, swap);
    else if (kind == 'i' && width == 4) v = load_scalar<std::int32_t>(p, swap);
    else if (kind == 'i' && width == 8) v = static_cast<double>(load_scalar<std::int64_t>(p, swap));
    else if ((kind == 'u' || kind == 'b') && width == 1) v = load_scalar<std::uint8_t>(p, false);
    else if (kind == 'u' && width == 2) v = load_scalar<std::uint16_t>(p, swap);
    else if (kind == 'u' && width == 4) v = load_scalar<std::uint32_t>(p, swap);
    else if (kind == 'u' && width == 8) v = static_cast<double>(load_scalar<std::uint64_t>(p, swap));
    else fail_file(src, "npy dtype {} is not supported", descr);
    out.values[i] = v;
  }
  if (order.starts_with("True") && shape.size() > 1) {
    // Fortran order: convert to row-major.
    std::vector<double> c(count);
    std::vector<std::size_t> idx(shape.size(), 0);
    for (std::size_t f = 0; f < count; ++f) {
      std::size_t row_major = 0;
      for (std::size_t d = 0; d < shape.size(); ++d) row_major = row_major * shape[d] + idx[d];
      c[row_major] = out.values[f];
      for (std::size_t d = 0; d < shape.size(); ++d) {  // Fortran: first index fastest
        if (++idx[d] < shape[d]) break;
        idx[d] = 0;
      }
    }
    out.values = std::move(c);
  }
  return out;
}

NpyArray read_npy(const std::filesystem::path& path) { return parse_npy(read_file(path), path); }

namespace {

template <typename T>
void write_npy(const std::filesystem::path& path, const std::vector<std::size_t>& shape, const std::vector<T>& values,
               const char* descr) {
  std::string dims;
  std::size_t count = 1;
  for (auto d : shape) {
    dims += std::to_string(d) + ",";
    count *= d;
  }
  if (shape.size() > 1) dims.pop_back();
  if (count != values.size()) fail_file(path, "shape does not match {} values", values.size());
  std::string header = fmt::format("{{'descr': '{}', 'fortran_order': False, 'shape': ({}), }}", descr, dims);
  const std::size_t total = 10 + header.size() + 1;
  header.append((64 - total % 64) % 64, ' ');
  header.push_back('\n');
  std::string bytes("\x93NUMPY\x01\x00", 8);
  bytes.push_back(static_cast<char>(header.size() & 0xff));
  bytes.push_back(static_cast<char>(header.size() >> 8));
  bytes += header;
  static_assert(std::endian::native == std::endian::little, "d2gs writes little-endian files");
  bytes.append(reinterpret_cast<const char*>(values.data()), values.size() * sizeof(T));
  write_file_atomic(path, bytes);
}

}  // namespace

void write_npy_f32(const std::filesystem::path& path, const std::vector<std::size_t>& shape,
                   const std::vector<float>& values) {
  write_npy(path, shape, values, "<f4");
}

void write_npy_f64(const std::filesystem::path& path, const std::vector<std::size_t>& shape,
                   const std::vector<double>& values) {
  write_npy(path, shape, values, "<f8");
}

}  // namespace d2gs
