#include "d2gs/model/ply.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <string_view>
#include <unordered_set>
#include <vector>

#include "d2gs/core/atomic_file.hpp"
#include "d2gs/core/error.hpp"

namespace d2gs {
namespace fs = std::filesystem;

namespace {

static_assert(std::endian::native == std::endian::little, "d2gs writes little-endian files");

// ---------------------------------------------------------------------------------------------------
// Header

enum class PlyType : std::uint8_t { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };
enum class PlyFormat { Ascii, BinaryLittleEndian, BinaryBigEndian };

std::size_t type_size(PlyType t) {
  switch (t) {
    case PlyType::Int8: case PlyType::UInt8: return 1;
    case PlyType::Int16: case PlyType::UInt16: return 2;
    case PlyType::Int32: case PlyType::UInt32: case PlyType::Float32: return 4;
    case PlyType::Float64: return 8;
  }
  return 1;
}

bool is_integer(PlyType t) { return t != PlyType::Float32 && t != PlyType::Float64; }

bool parse_type(std::string_view s, PlyType& out) {
  static constexpr std::pair<std::string_view, PlyType> names[] = {
      {"char", PlyType::Int8},     {"int8", PlyType::Int8},       {"uchar", PlyType::UInt8},
      {"uint8", PlyType::UInt8},   {"short", PlyType::Int16},     {"int16", PlyType::Int16},
      {"ushort", PlyType::UInt16}, {"uint16", PlyType::UInt16},   {"int", PlyType::Int32},
      {"int32", PlyType::Int32},   {"uint", PlyType::UInt32},     {"uint32", PlyType::UInt32},
      {"float", PlyType::Float32}, {"float32", PlyType::Float32}, {"double", PlyType::Float64},
      {"float64", PlyType::Float64}};
  for (const auto& [name, type] : names)
    if (s == name) {
      out = type;
      return true;
    }
  return false;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::Float32;  // value type (list items for lists)
  bool is_list = false;
  PlyType count_type = PlyType::UInt8;
};

struct PlyElement {
  std::string name;
  std::uint64_t count = 0;
  std::vector<PlyProperty> properties;
  int find(std::string_view property) const {
    for (std::size_t i = 0; i < properties.size(); ++i)
      if (properties[i].name == property) return static_cast<int>(i);
    return -1;
  }
  bool has_lists() const {
    return std::any_of(properties.begin(), properties.end(), [](const auto& p) { return p.is_list; });
  }
  // Bytes of one item in a binary file (lists counted as empty).
  std::size_t min_binary_size() const {
    std::size_t s = 0;
    for (const auto& p : properties) s += p.is_list ? type_size(p.count_type) : type_size(p.type);
    return s;
  }
};

struct PlyHeader {
  PlyFormat format = PlyFormat::BinaryLittleEndian;
  std::vector<PlyElement> elements;
  std::size_t data_offset = 0;
};

std::vector<std::string_view> split_words(std::string_view line) {
  std::vector<std::string_view> words;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    const std::size_t start = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (i > start) words.push_back(line.substr(start, i - start));
  }
  return words;
}

PlyHeader parse_header(std::string_view bytes, const fs::path& src) {
  // Magic: "ply" followed by a line end.
  if (bytes.size() < 4 || bytes.substr(0, 3) != "ply" || (bytes[3] != '\n' && bytes[3] != '\r'))
    fail_file(src, "not a PLY file (missing 'ply' magic line)");
  PlyHeader header;
  std::unordered_set<std::string> element_names, property_names;  // property names of the last element
  bool have_format = false, have_end = false;
  std::size_t pos = bytes.find('\n');
  if (pos == std::string_view::npos) fail_file(src, "PLY header has no end_header line");
  ++pos;
  int line_number = 1;
  while (pos < bytes.size()) {
    ++line_number;
    const std::size_t eol = bytes.find('\n', pos);
    if (eol == std::string_view::npos) break;  // an unterminated line cannot be end_header
    const std::string_view line = bytes.substr(pos, eol - pos);
    pos = eol + 1;
    const auto words = split_words(line);
    if (words.empty()) continue;
    const std::string_view key = words[0];
    if (key == "comment" || key == "obj_info") continue;
    if (key == "end_header") {
      have_end = true;
      break;
    }
    if (key == "format") {
      if (have_format) fail_file(src, "PLY header line {}: second 'format' line", line_number);
      if (words.size() != 3) fail_file(src, "PLY header line {}: malformed format line '{}'", line_number, printable(line));
      if (words[1] == "ascii") header.format = PlyFormat::Ascii;
      else if (words[1] == "binary_little_endian") header.format = PlyFormat::BinaryLittleEndian;
      else if (words[1] == "binary_big_endian") header.format = PlyFormat::BinaryBigEndian;
      else fail_file(src, "PLY header line {}: unknown format '{}'", line_number, printable(words[1]));
      if (!words[2].starts_with("1")) fail_file(src, "PLY header line {}: unsupported version '{}'", line_number, printable(words[2]));
      have_format = true;
    } else if (key == "element") {
      if (words.size() != 3) fail_file(src, "PLY header line {}: malformed element line '{}'", line_number, printable(line));
      PlyElement e;
      e.name = std::string(words[1]);
      const auto* b = words[2].data();
      const auto* end = b + words[2].size();
      const auto [p, ec] = std::from_chars(b, end, e.count);
      if (ec != std::errc() || p != end)
        fail_file(src, "PLY header line {}: element '{}' has an invalid count '{}'", line_number, printable(e.name),
                  printable(words[2]));
      if (!element_names.insert(e.name).second)
        fail_file(src, "PLY header line {}: duplicate element '{}'", line_number, printable(e.name));
      property_names.clear();
      header.elements.push_back(std::move(e));
    } else if (key == "property") {
      if (header.elements.empty()) fail_file(src, "PLY header line {}: property before any element", line_number);
      PlyProperty prop;
      if (words.size() >= 2 && words[1] == "list") {
        if (words.size() != 5) fail_file(src, "PLY header line {}: malformed list property '{}'", line_number, printable(line));
        if (!parse_type(words[2], prop.count_type) || !parse_type(words[3], prop.type))
          fail_file(src, "PLY header line {}: unknown property type in '{}'", line_number, printable(line));
        if (!is_integer(prop.count_type))
          fail_file(src, "PLY header line {}: list count type must be an integer type", line_number);
        prop.is_list = true;
        prop.name = std::string(words[4]);
      } else {
        if (words.size() != 3) fail_file(src, "PLY header line {}: malformed property line '{}'", line_number, printable(line));
        if (!parse_type(words[1], prop.type))
          fail_file(src, "PLY header line {}: unknown property type '{}'", line_number, printable(words[1]));
        prop.name = std::string(words[2]);
      }
      auto& element = header.elements.back();
      if (!property_names.insert(prop.name).second)
        fail_file(src, "PLY header line {}: duplicate property '{}' in element '{}'", line_number, printable(prop.name),
                  printable(element.name));
      element.properties.push_back(std::move(prop));
    } else {
      fail_file(src, "PLY header line {}: unexpected '{}'", line_number, printable(key));
    }
  }
  if (!have_end) fail_file(src, "PLY header has no end_header line (truncated or not a PLY file)");
  if (!have_format) fail_file(src, "PLY header has no format line");
  header.data_offset = pos;
  return header;
}

// ---------------------------------------------------------------------------------------------------
// Data: cursors over binary and ascii bodies. read() returns false at the end of the data.

template <typename T>
T load(const char* p, bool swap) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  if (swap) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}

struct Value {
  double number = 0;  // every PLY type converts exactly to double
  // Exact for float properties (float -> double -> float is the identity); values beyond the float
  // range become +-infinity (and are rejected by the callers' finiteness checks).
  float as_float() const {
    // IEEE round-to-nearest overflows from FLT_MAX + half an ulp (0x1.ffffffp127) upwards; written out
    // because the C++ standard leaves out-of-range conversions undefined.
    if (std::isfinite(number) && std::fabs(number) >= 0x1.ffffffp127)
      return number > 0 ? std::numeric_limits<float>::infinity() : -std::numeric_limits<float>::infinity();
    return static_cast<float>(number);
  }
};

double load_value(const char* p, PlyType t, bool swap) {
  switch (t) {
    case PlyType::Int8: return load<std::int8_t>(p, false);
    case PlyType::UInt8: return load<std::uint8_t>(p, false);
    case PlyType::Int16: return load<std::int16_t>(p, swap);
    case PlyType::UInt16: return load<std::uint16_t>(p, swap);
    case PlyType::Int32: return load<std::int32_t>(p, swap);
    case PlyType::UInt32: return load<std::uint32_t>(p, swap);
    case PlyType::Float32: return load<float>(p, swap);
    case PlyType::Float64: return load<double>(p, swap);
  }
  return 0;
}

class BinaryCursor {
public:
  BinaryCursor(std::string_view data, bool swap) : p_(data.data()), end_(data.data() + data.size()), swap_(swap) {}
  std::size_t remaining() const { return static_cast<std::size_t>(end_ - p_); }
  bool read(PlyType t, Value& v) {
    const std::size_t n = type_size(t);
    if (remaining() < n) return false;
    v.number = load_value(p_, t, swap_);
    p_ += n;
    return true;
  }
  bool skip(std::size_t bytes) {
    if (remaining() < bytes) return false;
    p_ += bytes;
    return true;
  }
  // Fixed-stride fast path: the address of the next `bytes` bytes, or nullptr.
  const char* take(std::size_t bytes) {
    if (remaining() < bytes) return nullptr;
    const char* at = p_;
    p_ += bytes;
    return at;
  }
  bool swap() const { return swap_; }

private:
  const char* p_;
  const char* end_;
  bool swap_;
};

class AsciiCursor {
public:
  explicit AsciiCursor(std::string_view data) : data_(data) {}
  std::size_t remaining() const { return data_.size() - pos_; }
  // Offset of the next token after white space (the size of the data when none is left).
  std::size_t next_token() {
    while (pos_ < data_.size() && is_space(data_[pos_])) ++pos_;
    return pos_;
  }
  // Returns false at the end of the data; throws (via `bad`) on a malformed number.
  template <typename Bad>
  bool read(PlyType t, Value& v, Bad&& bad) {
    while (pos_ < data_.size() && is_space(data_[pos_])) ++pos_;
    if (pos_ >= data_.size()) return false;
    const std::size_t start = pos_;
    while (pos_ < data_.size() && !is_space(data_[pos_])) ++pos_;
    std::string_view token = data_.substr(start, pos_ - start);
    const std::string_view original = token;
    if (token.size() > 1 && token[0] == '+') token.remove_prefix(1);
    const char* b = token.data();
    const char* e = b + token.size();
    std::from_chars_result r{};
    switch (t) {
      case PlyType::Float32: {
        float f = 0;
        r = std::from_chars(b, e, f);
        v.number = f;
        break;
      }
      case PlyType::Float64: r = std::from_chars(b, e, v.number); break;
      default: {
        std::int64_t i = 0;
        r = std::from_chars(b, e, i);
        if (r.ec == std::errc() && r.ptr == e && !in_range(t, i)) bad(original, "out of range for its type");
        v.number = static_cast<double>(i);
        break;
      }
    }
    // from_chars reports out-of-range floats (e.g. 1e-50 as float) as errors; accept them as the
    // rounded value (0 or the denormal) only for underflow, reject overflow below via the finite check.
    if (r.ec == std::errc::result_out_of_range && !is_integer(t)) {
      const double d = std::strtod(std::string(token).c_str(), nullptr);
      v.number = d;
      if (t == PlyType::Float32) v.number = static_cast<double>(v.as_float());
      r.ec = std::errc();
      r.ptr = e;
    }
    if (r.ec != std::errc() || r.ptr != e) bad(original, "is not a valid number");
    return true;
  }

private:
  static bool is_space(char c) { return c == ' ' || c == '\t' || c == '\n' || c == '\r' || c == '\v' || c == '\f'; }
  static bool in_range(PlyType t, std::int64_t i) {
    switch (t) {
      case PlyType::Int8: return i >= -128 && i <= 127;
      case PlyType::UInt8: return i >= 0 && i <= 255;
      case PlyType::Int16: return i >= -32768 && i <= 32767;
      case PlyType::UInt16: return i >= 0 && i <= 65535;
      case PlyType::Int32: return i >= std::numeric_limits<std::int32_t>::min() && i <= std::numeric_limits<std::int32_t>::max();
      case PlyType::UInt32: return i >= 0 && i <= std::numeric_limits<std::uint32_t>::max();
      default: return true;
    }
  }
  std::string_view data_;
  std::size_t pos_ = 0;
};

// Reads every element of `header` in file order, skipping all but `target`. For every item of the
// target and every scalar property p with slot[p] >= 0, calls sink(item_index, slot[p], value). List
// properties are skipped in every element. The data must end where the last element's does: a binary
// file exactly, an ascii file but for white space; anything after it (trailing bytes, or an element
// count lower than the data) is an error, as is data that ends before every element's is read.
class ElementReader {
  static std::size_t line_ends(std::string_view s) { return static_cast<std::size_t>(std::count(s.begin(), s.end(), '\n')); }

public:
  ElementReader(std::string_view bytes, const PlyHeader& header, const fs::path& src)
      : data_(bytes.substr(std::min(header.data_offset, bytes.size()))), header_(header), src_(src),
        header_lines_(line_ends(bytes.substr(0, bytes.size() - data_.size()))) {}

  template <typename Sink>
  void read(const PlyElement& target, const std::vector<int>& slot, Sink&& sink) {
    if (header_.format == PlyFormat::Ascii) {
      AsciiCursor cur(data_);
      for (const auto& e : header_.elements) {
        check_count_ascii(e, cur.remaining());
        walk_ascii(cur, e, &e == &target ? &slot : nullptr, sink);
      }
      if (const std::size_t at = cur.next_token(); at < data_.size()) {
        const std::size_t eol = data_.find_first_of("\r\n", at);
        const std::string_view text = data_.substr(at, eol == std::string_view::npos ? eol : eol - at);
        fail_file(src_, "line {}: unexpected data '{}' after the last item of element '{}' (trailing text, or the "
                  "header declares fewer items than the file holds)", header_lines_ + 1 + line_ends(data_.substr(0, at)),
                  printable(text), header_.elements.back().name);
      }
    } else {
      BinaryCursor cur(data_, header_.format == PlyFormat::BinaryBigEndian);
      for (const auto& e : header_.elements) {
        check_count_binary(e, cur.remaining());
        walk_binary(cur, e, &e == &target ? &slot : nullptr, sink);
      }
      if (cur.remaining() != 0)
        fail_file(src_, "{} unexpected bytes after the last item of element '{}' (offset {}; trailing bytes, or the "
                  "header declares fewer items than the file holds)", cur.remaining(), header_.elements.back().name,
                  header_.data_offset + (data_.size() - cur.remaining()));
    }
  }

private:
  // Caps counts by the bytes that remain, before anything is allocated or looped over.
  void check_count_binary(const PlyElement& e, std::size_t remaining) const {
    const std::size_t item = e.min_binary_size();
    if (item == 0 || e.count == 0) return;
    if (e.count > remaining / item)
      fail_file(src_, "truncated data: element '{}' declares {} items of at least {} bytes but only {} bytes remain",
                e.name, e.count, item, remaining);
  }
  void check_count_ascii(const PlyElement& e, std::size_t remaining) const {
    const std::size_t per_item = e.properties.size();  // at least one token per property
    if (per_item == 0 || e.count == 0) return;
    // n tokens need at least 2n - 1 characters.
    if (e.count > (remaining + 1) / 2 / per_item)
      fail_file(src_, "truncated data: element '{}' declares {} items but only {} bytes of text remain", e.name,
                e.count, remaining);
  }

  [[noreturn]] void truncated(const PlyElement& e, std::uint64_t item, const PlyProperty& p) const {
    fail_file(src_, "truncated data: element '{}' ends in item {} of {} (property '{}')", e.name, item, e.count, p.name);
  }

  std::uint64_t list_count(const PlyElement& e, std::uint64_t item, const PlyProperty& p, const Value& v) const {
    if (v.number < 0)
      fail_file(src_, "element '{}' item {}: list '{}' has negative length {}", e.name, item, p.name, v.number);
    return static_cast<std::uint64_t>(v.number);
  }

  template <typename Sink>
  void walk_binary(BinaryCursor& cur, const PlyElement& e, const std::vector<int>* slot, Sink& sink) const {
    if (e.properties.empty() || e.count == 0) return;
    if (!e.has_lists()) {
      const std::size_t stride = e.min_binary_size();
      if (!slot) {
        cur.skip(static_cast<std::size_t>(e.count) * stride);  // count was capped by the remaining bytes
        return;
      }
      // Fixed stride: offsets of the wanted properties.
      struct Wanted { std::size_t offset; PlyType type; int slot; };
      std::vector<Wanted> wanted;
      std::size_t offset = 0;
      for (std::size_t p = 0; p < e.properties.size(); ++p) {
        if ((*slot)[p] >= 0) wanted.push_back({offset, e.properties[p].type, (*slot)[p]});
        offset += type_size(e.properties[p].type);
      }
      const bool swap = cur.swap();
      for (std::uint64_t i = 0; i < e.count; ++i) {
        const char* row = cur.take(stride);
        if (!row) truncated(e, i, e.properties.front());
        for (const auto& w : wanted) {
          Value v;
          v.number = load_value(row + w.offset, w.type, swap);
          sink(i, w.slot, v);
        }
      }
      return;
    }
    for (std::uint64_t i = 0; i < e.count; ++i) {
      for (std::size_t p = 0; p < e.properties.size(); ++p) {
        const auto& prop = e.properties[p];
        Value v;
        if (prop.is_list) {
          if (!cur.read(prop.count_type, v)) truncated(e, i, prop);
          const std::uint64_t n = list_count(e, i, prop, v);
          const std::size_t item = type_size(prop.type);
          if (n > cur.remaining() / item) truncated(e, i, prop);
          cur.skip(static_cast<std::size_t>(n) * item);
        } else {
          if (!cur.read(prop.type, v)) truncated(e, i, prop);
          if (slot && (*slot)[p] >= 0) sink(i, (*slot)[p], v);
        }
      }
    }
  }

  template <typename Sink>
  void walk_ascii(AsciiCursor& cur, const PlyElement& e, const std::vector<int>* slot, Sink& sink) const {
    if (e.properties.empty() || e.count == 0) return;
    for (std::uint64_t i = 0; i < e.count; ++i) {
      for (std::size_t p = 0; p < e.properties.size(); ++p) {
        const auto& prop = e.properties[p];
        const auto bad = [&](std::string_view token, const char* why) {
          fail_file(src_, "element '{}' item {} property '{}': '{}' {}", e.name, i, prop.name, printable(token), why);
        };
        Value v;
        if (prop.is_list) {
          if (!cur.read(prop.count_type, v, bad)) truncated(e, i, prop);
          const std::uint64_t n = list_count(e, i, prop, v);
          for (std::uint64_t k = 0; k < n; ++k)
            if (!cur.read(prop.type, v, bad)) truncated(e, i, prop);
        } else {
          if (!cur.read(prop.type, v, bad)) truncated(e, i, prop);
          if (slot && (*slot)[p] >= 0) sink(i, (*slot)[p], v);
        }
      }
    }
  }

  std::string_view data_;
  const PlyHeader& header_;
  const fs::path& src_;
  std::size_t header_lines_;  // line ends before the data: the data's first line is the next one
};

const PlyElement& vertex_element(const PlyHeader& header, const fs::path& src) {
  for (const auto& e : header.elements)
    if (e.name == "vertex") return e;
  fail_file(src, "PLY file has no 'vertex' element");
}

// Caps the vertex count by the bytes after the header (each item needs at least its minimal size), so
// that absurd counts fail before the caller allocates anything.
void check_vertex_count(std::string_view bytes, const PlyHeader& header, const PlyElement& vertex,
                        const fs::path& src) {
  if (vertex.count == 0) return;
  const std::size_t remaining = bytes.size() - std::min(header.data_offset, bytes.size());
  const std::size_t props = vertex.properties.size();
  const std::size_t min_item = header.format == PlyFormat::Ascii ? (props == 0 ? 0 : 2 * props - 1)
                                                                 : vertex.min_binary_size();
  if (min_item == 0) fail_file(src, "element 'vertex' has no properties");
  if (vertex.count > remaining / min_item)
    fail_file(src, "truncated data: element 'vertex' declares {} items but only {} bytes follow the header",
              vertex.count, remaining);
}

int require_property(const PlyElement& e, std::string_view name, const fs::path& src) {
  const int p = e.find(name);
  if (p < 0) fail_file(src, "missing required property '{}' in element 'vertex'", name);
  if (e.properties[static_cast<std::size_t>(p)].is_list)
    fail_file(src, "property '{}' of element 'vertex' is a list, expected a number", name);
  return p;
}

// ---------------------------------------------------------------------------------------------------
// Writing

std::string gaussian_property_name(std::size_t column, int k_rest) {
  const std::size_t rest = static_cast<std::size_t>(k_rest) * 3;
  static constexpr const char* head[] = {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"};
  static constexpr const char* tail[] = {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"};
  if (column < 9) return head[column];
  if (column < 9 + rest) return "f_rest_" + std::to_string(column - 9);
  return tail[column - 9 - rest];
}

void append_f32(std::string& out, float v) {
  char b[4];
  std::memcpy(b, &v, 4);
  out.append(b, 4);
}

}  // namespace

// ---------------------------------------------------------------------------------------------------
// Gaussians

void write_gaussians_ply(const fs::path& path, const Gaussians& model) {
  try {
    model.validate();
  } catch (const Error& e) {
    fail_file(path, "cannot write an invalid model: {}", e.what());
  }
  const std::size_t n = model.size();
  const int k = model.sh_rest_count();
  const std::size_t columns = 9 + static_cast<std::size_t>(k) * 3 + 8;

  std::string header = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(n) + "\n";
  for (std::size_t c = 0; c < columns; ++c) header += "property float " + gaussian_property_name(c, k) + "\n";
  header += "end_header\n";

  AtomicFile file(path);
  file.stream().write(header.data(), static_cast<std::streamsize>(header.size()));
  std::string chunk;
  constexpr std::size_t kRowsPerChunk = 4096;
  chunk.reserve(kRowsPerChunk * columns * 4);
  const auto check = [&](float v, std::size_t i, std::size_t c) {
    if (!std::isfinite(v))
      fail_file(path, "cannot write Gaussian {}: property '{}' is {}", i, gaussian_property_name(c, k),
                std::isnan(v) ? "NaN" : "infinite");
    return v;
  };
  for (std::size_t i = 0; i < n; ++i) {
    std::size_t c = 0;
    for (int j = 0; j < 3; ++j, ++c) append_f32(chunk, check(model.means[i * 3 + j], i, c));
    for (int j = 0; j < 3; ++j, ++c) append_f32(chunk, 0.0f);
    for (int j = 0; j < 3; ++j, ++c) append_f32(chunk, check(model.sh_dc[i * 3 + j], i, c));
    // File order: channel-major (all red coefficients, then green, then blue); memory: N x K x 3.
    for (int ch = 0; ch < 3; ++ch)
      for (int j = 0; j < k; ++j, ++c)
        append_f32(chunk, check(model.sh_rest[(i * static_cast<std::size_t>(k) + static_cast<std::size_t>(j)) * 3 + ch], i, c));
    append_f32(chunk, check(model.opacity_logits[i], i, c++));
    for (int j = 0; j < 3; ++j, ++c) append_f32(chunk, check(model.log_scales[i * 3 + j], i, c));
    for (int j = 0; j < 4; ++j, ++c) append_f32(chunk, check(model.quats[i * 4 + j], i, c));
    if ((i + 1) % kRowsPerChunk == 0 || i + 1 == n) {
      file.stream().write(chunk.data(), static_cast<std::streamsize>(chunk.size()));
      chunk.clear();
    }
  }
  file.commit();
}

Gaussians read_gaussians_ply(const fs::path& path) { return parse_gaussians_ply(read_file(path), path); }

Gaussians parse_gaussians_ply(std::string_view bytes, const fs::path& src) {
  const PlyHeader header = parse_header(bytes, src);
  const PlyElement& vertex = vertex_element(header, src);

  // SH degree from the number of f_rest_* properties, which must be f_rest_0 .. f_rest_{M-1}.
  std::size_t rest_count = 0;
  for (const auto& p : vertex.properties)
    if (p.name.starts_with("f_rest_")) ++rest_count;
  int degree = -1;
  for (int d = 0; d <= kMaxShDegree; ++d)
    if (static_cast<std::size_t>(sh_coeff_count(d) - 1) * 3 == rest_count) degree = d;
  if (degree < 0)
    fail_file(src, "{} f_rest_* properties; expected 0, 9, 24 or 45 (SH degree 0 to 3)", rest_count);
  const int k = sh_coeff_count(degree) - 1;

  // Destination of each property: (array, stride, offset) encoded as a slot into `targets`.
  struct Target {
    std::vector<float>* array;
    std::size_t stride;
    std::size_t offset;
    float* base = nullptr;  // array->data() + offset, set once the model is sized
  };
  Gaussians model;
  std::vector<Target> targets;
  std::vector<std::string> target_names;
  std::vector<int> slot(vertex.properties.size(), -1);
  const auto want = [&](const std::string& name, std::vector<float>* array, std::size_t stride, std::size_t offset) {
    const int p = require_property(vertex, name, src);
    slot[static_cast<std::size_t>(p)] = static_cast<int>(targets.size());
    targets.push_back({array, stride, offset});
    target_names.push_back(name);
  };
  static constexpr const char* xyz[] = {"x", "y", "z"};
  for (std::size_t j = 0; j < 3; ++j) want(xyz[j], &model.means, 3, j);
  for (std::size_t j = 0; j < 3; ++j) want("f_dc_" + std::to_string(j), &model.sh_dc, 3, j);
  const std::size_t ku = static_cast<std::size_t>(k);
  for (std::size_t ch = 0; ch < 3; ++ch)
    for (std::size_t j = 0; j < ku; ++j) want("f_rest_" + std::to_string(ch * ku + j), &model.sh_rest, ku * 3, j * 3 + ch);
  want("opacity", &model.opacity_logits, 1, 0);
  for (std::size_t j = 0; j < 3; ++j) want("scale_" + std::to_string(j), &model.log_scales, 3, j);
  for (std::size_t j = 0; j < 4; ++j) want("rot_" + std::to_string(j), &model.quats, 4, j);

  check_vertex_count(bytes, header, vertex, src);  // before anything is allocated
  model.resize(static_cast<std::size_t>(vertex.count), degree);
  if (!model.empty())  // (no pointer arithmetic on the null data() of empty arrays)
    for (auto& t : targets) t.base = t.array->data() + t.offset;

  ElementReader reader(bytes, header, src);
  reader.read(vertex, slot, [&](std::uint64_t i, int s, const Value& v) {
    const Target& t = targets[static_cast<std::size_t>(s)];
    const float f = v.as_float();
    if (!std::isfinite(f)) [[unlikely]]
      fail_file(src, "vertex {}: property '{}' is {}", i, target_names[static_cast<std::size_t>(s)],
                std::isnan(f) ? "NaN" : (std::isfinite(v.number) ? "out of float range" : "infinite"));
    t.base[static_cast<std::size_t>(i) * t.stride] = f;
  });
  return model;
}

// ---------------------------------------------------------------------------------------------------
// Point clouds

void write_point_cloud_ply(const fs::path& path, const PointCloud& cloud) {
  if (cloud.colors.size() != cloud.positions.size())
    fail_file(path, "point cloud has {} positions but {} colours", cloud.positions.size(), cloud.colors.size());
  if (!cloud.normals.empty() && cloud.normals.size() != cloud.positions.size())
    fail_file(path, "point cloud has {} positions but {} normals", cloud.positions.size(), cloud.normals.size());
  const std::size_t n = cloud.size();
  std::string bytes = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(n) +
                      "\nproperty float x\nproperty float y\nproperty float z\n"
                      "property float nx\nproperty float ny\nproperty float nz\n"
                      "property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n";
  bytes.reserve(bytes.size() + n * 27);
  for (std::size_t i = 0; i < n; ++i) {
    for (int j = 0; j < 3; ++j) {
      const float v = cloud.positions[i][j];
      if (!std::isfinite(v)) fail_file(path, "cannot write point {}: coordinate {} is {}", i, "xyz"[j], std::isnan(v) ? "NaN" : "infinite");
      append_f32(bytes, v);
    }
    for (int j = 0; j < 3; ++j) append_f32(bytes, cloud.normals.empty() ? 0.0f : cloud.normals[i][j]);
    for (int j = 0; j < 3; ++j) bytes.push_back(static_cast<char>(cloud.colors[i][j]));
  }
  write_file_atomic(path, bytes);
}

PointCloud read_point_cloud_ply(const fs::path& path) { return parse_point_cloud_ply(read_file(path), path); }

PointCloud parse_point_cloud_ply(std::string_view bytes, const fs::path& src) {
  const PlyHeader header = parse_header(bytes, src);
  const PlyElement& vertex = vertex_element(header, src);
  std::vector<int> slot(vertex.properties.size(), -1);
  // Slots 0-2: position, 3-5: colour.
  static constexpr const char* xyz[] = {"x", "y", "z"};
  for (int j = 0; j < 3; ++j) slot[static_cast<std::size_t>(require_property(vertex, xyz[j], src))] = j;
  static constexpr std::array<std::array<const char*, 3>, 3> colour_names = {
      {{"red", "diffuse_red", "r"}, {"green", "diffuse_green", "g"}, {"blue", "diffuse_blue", "b"}}};
  std::array<int, 3> colour_prop{-1, -1, -1};
  for (int c = 0; c < 3; ++c)
    for (const char* name : colour_names[static_cast<std::size_t>(c)]) {
      const int p = vertex.find(name);
      if (p >= 0 && !vertex.properties[static_cast<std::size_t>(p)].is_list) {
        colour_prop[static_cast<std::size_t>(c)] = p;
        break;
      }
    }
  const int found = static_cast<int>(std::count_if(colour_prop.begin(), colour_prop.end(), [](int p) { return p >= 0; }));
  if (found != 0 && found != 3)
    fail_file(src, "point cloud has only some colour properties (need red, green and blue, or none)");
  std::array<PlyType, 3> colour_type{};
  for (int c = 0; c < 3 && found == 3; ++c) {
    const auto p = static_cast<std::size_t>(colour_prop[static_cast<std::size_t>(c)]);
    slot[p] = 3 + c;
    colour_type[static_cast<std::size_t>(c)] = vertex.properties[p].type;
  }

  check_vertex_count(bytes, header, vertex, src);  // before anything is allocated
  PointCloud cloud;
  const auto n = static_cast<std::size_t>(vertex.count);
  cloud.positions.assign(n, glm::vec3(0.0f));
  // Points without colours are mid-grey.
  cloud.colors.assign(n, glm::u8vec3(128));

  ElementReader reader(bytes, header, src);
  reader.read(vertex, slot, [&](std::uint64_t i, int s, const Value& v) {
    const auto idx = static_cast<std::size_t>(i);
    if (s < 3) {
      const float f = v.as_float();
      if (!std::isfinite(f))
        fail_file(src, "vertex {}: property '{}' is {}", i, xyz[s], std::isnan(f) ? "NaN" : "not finite");
      cloud.positions[idx][s] = f;
      return;
    }
    const int c = s - 3;
    const PlyType t = colour_type[static_cast<std::size_t>(c)];
    double value = v.number;
    if (std::isnan(value))
      fail_file(src, "vertex {}: colour property '{}' is NaN", i,
                vertex.properties[static_cast<std::size_t>(colour_prop[static_cast<std::size_t>(c)])].name);
    if (!is_integer(t)) value *= 255.0;                                     // float colours in [0, 1]
    else if (t == PlyType::UInt16 || t == PlyType::Int16) value /= 257.0;   // 16-bit colours
    value = std::clamp(std::round(value), 0.0, 255.0);
    cloud.colors[idx][c] = static_cast<std::uint8_t>(value);
  });
  return cloud;
}

}  // namespace d2gs
